"""Shared pytest configuration for the localize test suite."""

import os

import matplotlib

# Notebook kernels started by nbval inherit this process's environment; an
# MPLBACKEND=Agg set by a CI system would stop their inline figures from
# appearing and make stored outputs differ. The kernel picks its own backend.
os.environ.pop("MPLBACKEND", None)
matplotlib.use("Agg")

from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import pytest  # noqa: E402
from hypothesis import settings  # noqa: E402

# Property tests are derandomised (the same examples on every run, like every
# other seeded test here) and have no per-example deadline: this suite runs on
# a shared 2-core machine, and speed is measured by benchmarks/, not by tests.
settings.register_profile("localize", derandomize=True, deadline=None, print_blob=True)
settings.load_profile("localize")

ROOT = Path(__file__).resolve().parent


def data_dir() -> Path | None:
    """The real robot data folder: $LOCALIZE_DATA, or ../shared/data beside the checkout."""
    env = os.environ.get("LOCALIZE_DATA")
    candidates = [Path(env)] if env else []
    candidates.append(ROOT.parent / "shared" / "data")
    for c in candidates:
        if c.is_dir():
            return c
    return None


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


@pytest.fixture(scope="session")
def shared_data():
    d = data_dir()
    if d is None:
        pytest.skip("real robot data not found: set LOCALIZE_DATA or place it at ../shared/data")
    return d


class GPS:
    """A toy sensor for doctests: it measures a pose's x coordinate with Gaussian noise ``sigma`` (metres)."""

    def __init__(self, sigma: float = 0.5) -> None:
        self.sigma = sigma

    def log_likelihood(self, poses, z):
        return -0.5 * ((poses[:, 0] - z) / self.sigma) ** 2


def toy_mcl():
    """The filter of the ``MCL`` method doctests: 101 equally weighted particles on ``x = 0, 0.1, ..., 10`` m
    (``y = theta = 0``), a motion ``u`` that shifts every particle by ``u`` metres along x, and a :class:`GPS`
    sensor with 0.5 m noise; seeded with ``np.random.default_rng(0)``."""
    from localize.mcl import MCL

    particles = np.column_stack([np.linspace(0, 10, 101), np.zeros(101), np.zeros(101)])
    shift = lambda poses, u, rng: poses + [u, 0.0, 0.0]  # noqa: E731
    return MCL(particles, shift, GPS(0.5), rng=np.random.default_rng(0))


def temporary_files(factory: pytest.TempPathFactory):
    """The doctests' temporary files, ``(tmp_dir, tmp_text)``, made under pytest's temporary folder ``factory``
    (which keeps the last three runs and removes older ones)."""

    def tmp_dir() -> Path:
        """A fresh empty folder, for an example that writes files of its own."""
        return factory.mktemp("doctest")

    def tmp_text(name: str, text: str) -> Path:
        """The file ``name`` in a fresh folder, holding ``text``: the input of a reader's example."""
        p = tmp_dir() / name
        p.write_text(text)
        return p

    return tmp_dir, tmp_text


@pytest.fixture(autouse=True)
def _doctest_namespace(doctest_namespace, tmp_path_factory):
    """Doctests in localize see numpy as ``np``, the toy filter of the MCL examples (``GPS``, ``toy_mcl``),
    and the temporary files of the reader and writer examples (``tmp_dir``, ``tmp_text``)."""
    doctest_namespace["np"] = np
    doctest_namespace["GPS"] = GPS
    doctest_namespace["toy_mcl"] = toy_mcl
    doctest_namespace["tmp_dir"], doctest_namespace["tmp_text"] = temporary_files(tmp_path_factory)


# The book's .py files (book/src/) are jupytext twins of the notebooks, not modules:
# keep --doctest-modules from importing (and so running) them. The homework
# template is meant to fail until a student fills it in.
collect_ignore_glob = ["book/*.py", "book/src/*", "book/homework/*", "book/_build/*", "_build/*", "benchmarks/*", ".ci/*"]
