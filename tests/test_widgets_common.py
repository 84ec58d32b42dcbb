"""Checks every widget module against the book's widget convention, without a browser.

Each ``localize.widgets.<topic>`` module (public name, no leading underscore)
exposes

``DEMOS: dict[str, Callable[[], Figure]]``
    demo name -> zero-argument callable that runs the widget's callback once
    with its default parameters and returns a matplotlib Figure;

``DEMO_VARIANTS: dict[str, list[Callable[[], Figure]]]`` (optional)
    demo name -> callables with other parameter values whose figures must
    differ from the default demo's figure (and from each other).

The tests below iterate over whatever modules exist, so a chapter's widget is
checked as soon as its module lands. They check that a demo returns a new
Figure with at least one Axes holding artists, that it is deterministic (two
calls give byte-identical PNGs, which is also what the browser test relies on
when it moves a slider back), that the demos of one module do not share state
(drawing them in reverse order changes nothing), and that each declared
variant really redraws differently. Redraw speed is measured by
``benchmarks/bench_widgets.py``, not here.
"""

from __future__ import annotations

import importlib
import io
import pkgutil

import matplotlib
import pytest

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

import localize.widgets  # noqa: E402

# Low resolution keeps the byte comparisons fast; any change of the drawing still shows.
DPI = 40


def _module_names() -> list[str]:
    return sorted(f"localize.widgets.{m.name}" for m in pkgutil.iter_modules(localize.widgets.__path__)
                  if not m.name.startswith("_"))


MODULES = _module_names()
_DEFAULT_PNG: dict[tuple[str, str], bytes] = {}  # (module, demo) -> PNG of the default figure, reused across tests
_params = MODULES or [pytest.param(None, marks=pytest.mark.skip(reason="no localize.widgets.<topic> module yet"))]


def _png(fig: Figure) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=DPI)
    return buf.getvalue()


def _render(demo, where: str, close: bool = True) -> bytes:
    """Call a demo, check it returned a non-empty Figure, return its PNG bytes (and close the figure)."""
    fig = demo()
    try:
        assert isinstance(fig, Figure), f"{where} returned {type(fig).__name__}, expected a matplotlib Figure"
        assert fig.axes, f"{where} returned a Figure without Axes"
        assert any(ax.get_children() and (ax.lines or ax.collections or ax.images or ax.patches or ax.texts
                                          or ax.artists) for ax in fig.axes), \
            f"{where} returned Axes without any lines, collections, images, patches or texts"
        return _png(fig)
    finally:
        if close:
            plt.close(fig)


def _demos(modname: str) -> dict:
    mod = importlib.import_module(modname)
    demos = getattr(mod, "DEMOS", None)
    assert isinstance(demos, dict) and demos, (
        f"{modname} has no DEMOS dict: every widget module maps demo names to zero-argument callables "
        "returning the default figure (see tests/test_widgets_common.py)")
    for name, demo in demos.items():
        assert isinstance(name, str) and callable(demo), f"{modname}.DEMOS[{name!r}] must be a callable"
    return demos


@pytest.mark.parametrize("modname", _params)
def test_demos_return_new_deterministic_figures(modname):
    demos = _demos(modname)
    first = {}
    for name, demo in demos.items():
        fig = demo()
        first[name] = (fig, _render(lambda fig=fig: fig, f"{modname}.DEMOS[{name!r}]()", close=False))
    try:
        # Second pass in reverse order: a demo that reads state another demo left behind
        # (a module-level figure, rng or cache mutated by a callback) shows up as different bytes.
        for name in reversed(list(demos)):
            fig = demos[name]()
            assert fig is not first[name][0], (
                f"{modname}.DEMOS[{name!r}]() returned the same Figure twice: a module-level figure is state "
                "shared between widgets; build a new Figure in each call")
            again = _render(lambda fig=fig: fig, f"{modname}.DEMOS[{name!r}]()")
            assert again == first[name][1], (
                f"{modname}.DEMOS[{name!r}]() drew a different PNG on a second call: the callback is not "
                "deterministic (unseeded rng?) or shares state with another widget")
            _DEFAULT_PNG[modname, name] = again
    finally:
        for fig, _ in first.values():
            plt.close(fig)


@pytest.mark.parametrize("modname", _params)
def test_variants_redraw_differently(modname):
    demos = _demos(modname)
    mod = importlib.import_module(modname)
    variants = getattr(mod, "DEMO_VARIANTS", None)
    if not variants:
        pytest.skip(f"{modname} declares no DEMO_VARIANTS")
    for name, alts in variants.items():
        assert name in demos, f"{modname}.DEMO_VARIANTS names {name!r}, which is not in DEMOS {sorted(demos)}"
        assert len(alts) >= 1, f"{modname}.DEMO_VARIANTS[{name!r}] is empty"
        default = _DEFAULT_PNG.get((modname, name)) or _render(demos[name], f"{modname}.DEMOS[{name!r}]()")
        seen = {default: "default"}
        for i, alt in enumerate(alts):
            png = _render(alt, f"{modname}.DEMO_VARIANTS[{name!r}][{i}]()")
            assert png not in seen, (
                f"{modname}.DEMO_VARIANTS[{name!r}][{i}] draws the same PNG as {seen.get(png)}: "
                "changing this parameter does not change the figure")
            seen[png] = f"variant {i}"
