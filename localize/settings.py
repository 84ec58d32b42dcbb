"""The settings of a log run, each written once: :class:`RunSettings`.

One frozen dataclass holds every setting of ``localize run`` (and of the
library's :func:`localize.pipeline.localize_log`) with its default, unit,
valid range and one-line help, as field metadata. From it come

* the command line's filter options (:func:`add_arguments`, :func:`from_namespace`):
  the flag of a setting is its field name with dashes (``skip_short_beams`` is
  ``--skip-short-beams``), its ``--help`` text is the field's help, and a value is
  checked when parsed by the same :mod:`localize._checks` helper as in the
  library, with the same wording (``argument --temper: expected a number in (0, 1]; got 2``);
* the mapping of a ROS AMCL parameter file (:func:`with_amcl`);
* the ``settings`` section of ``summary.json`` (:meth:`RunSettings.summary`).

The pipeline, the benchmarks and chapter 9 read it. A setting changed for one
run is a new object, ``dataclasses.replace(settings, beams=60)`` (checked
again), never a changed one.

Examples
--------
>>> s = RunSettings()
>>> s.sigma_hit, s.temper, s.skip_short_beams
(0.2, 0.3, 1.0)
>>> RunSettings(temper=2)
Traceback (most recent call last):
...
ValueError: temper must be a number in (0, 1]; got 2
>>> describe("sigma_hit")
'sigma_hit (metres, > 0, default 0.2): sensor noise: standard deviation of a beam about the map'
"""

from __future__ import annotations

import argparse
import math
from dataclasses import MISSING, dataclass, field, fields, replace
from typing import Any, Callable, Mapping

from ._checks import (
    check_alphas,
    check_choice,
    check_count,
    check_interval,
    check_nonnegative,
    check_number,
    check_positive,
    check_probability,
)

__all__ = ["RunSettings", "DEFAULTS", "LEGACY_NAMES", "describe", "explain", "CLI_GROUPS", "add_arguments", "from_namespace", "parse_options",
           "given_options",
           "with_amcl", "setting_names", "argparse_type", "check_particles", "jsonable"]


# ============================================================================ checks (from localize._checks)
def check_particles(value: Any, name: str) -> int | str:
    """A number of particles (a whole number >= 1) or ``"auto"``."""
    if isinstance(value, str) and value.strip().lower() == "auto":
        return "auto"
    try:
        return check_count(value, name)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a whole number >= 1 or 'auto'; got {value!r}") from None


def _penalty(value: Any, name: str) -> float:
    if isinstance(value, str) and value.strip().lower() in ("inf", "infinity"):
        return math.inf
    try:
        v = float(value) if not isinstance(value, bool) else math.nan
    except (TypeError, ValueError):
        v = math.nan
    if v == math.inf:
        return v
    try:
        return check_positive(value, name, "nats")
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a finite number of nats > 0 or 'inf'; got {value!r}") from None


def _count0(value: Any, name: str) -> int:
    return check_count(value, name, minimum=0)


def _fraction(value: Any, name: str) -> float:
    return check_interval(value, name, 0, 1, open_high=True, what="a fraction")


def _unit(value: Any, name: str) -> float:
    return check_interval(value, name, 0, 1, open_low=True)


def _open_unit(value: Any, name: str) -> float:
    return check_interval(value, name, 0, 1, open_low=True, open_high=True)


def _metres(value: Any, name: str) -> float:
    return check_positive(value, name, "metres")


def _metres0(value: Any, name: str) -> float:
    return check_nonnegative(value, name, "metres")


def _optional(check: Callable[[Any, str], Any]) -> Callable[[Any, str], Any]:
    def opt(value: Any, name: str) -> Any:
        return None if value is None else check(value, name)
    return opt


def _choice(*choices: str) -> Callable[[Any, str], str]:
    def check(value: Any, name: str) -> str:
        return check_choice(value, name, choices)
    return check


def _flag(value: Any, name: str) -> bool:
    if not isinstance(value, bool):
        raise TypeError(f"{name} must be True or False; got {value!r}")
    return value


def _pair(value: Any, name: str) -> tuple[float, float]:
    return _floats(value, name, 2, check_nonnegative)


def _floats(value: Any, name: str, n: int, check: Callable[[Any, str], float]) -> tuple:
    v = tuple(value) if isinstance(value, (tuple, list)) else (value,)
    if len(v) != n:
        raise ValueError(f"{name} must hold {n} numbers; got {value!r}")
    return tuple(check(x, name) for x in v)


def _alphas(value: Any, name: str) -> tuple[float, ...]:
    return tuple(float(a) for a in check_alphas(value, 4, name))


def _std3(value: Any, name: str) -> tuple[float, ...]:
    return _floats(value, name, 3, check_positive)


def _pose3(value: Any, name: str) -> tuple[float, float, float]:
    return _floats(value, name, 3, check_number)


def _params(value: Any, name: str) -> dict:
    if not isinstance(value, Mapping):
        raise TypeError(f"{name} must be a dict of sensor model keyword arguments; got {type(value).__name__}")
    return dict(value)


def setting(default: Any, help: str, check: Callable[[Any, str], Any], *, unit: str = "", valid: str = "",
            flag: bool = True, metavar: Any = None, nargs: int | None = None, choices: tuple | None = None,
            aliases: tuple[str, ...] = (), cli_help: str | None = None) -> Any:
    """A :class:`RunSettings` field: default, one-line ``help``, ``check`` (a :mod:`localize._checks` helper),
    ``unit``, ``valid`` range (words), and how the command line shows it (``flag`` False: library only;
    ``cli_help``: the setting's longer explanation and rationale, ``{default}`` replaced by the default,
    read by :func:`explain`; ``--help`` shows the one line of :data:`CLI_GROUPS` instead).

    >>> f = setting(0.5, "a threshold", check_probability, valid="[0, 1]")
    >>> f.default, f.metadata["valid"], f.metadata["flag"]
    (0.5, '[0, 1]', True)
    """
    meta = dict(help=help, check=check, unit=unit, valid=valid, flag=flag, metavar=metavar, nargs=nargs,
                choices=choices, aliases=aliases, cli_help=cli_help or help)
    if isinstance(default, dict):
        return field(default_factory=lambda: dict(default), metadata=meta)
    return field(default=default, metadata=meta)


# ============================================================================ the settings
@dataclass(frozen=True)
class RunSettings:
    """Every setting of a log run once: default, unit, range and help in each field's metadata.

    The first 22 fields are the filter options of ``localize run`` (``--particles`` ...
    ``--odometry-sign``, in the order of ``--help``), then ``track`` (``--track``), ``initial_pose`` and
    ``initial_std`` (``--initial-pose``, ``--initial-std``);
    the rest are library settings without a flag, which an AMCL parameter file or
    an experiment may set. Values are checked (and lists made tuples) when the
    object is made; see :func:`describe` for one setting's meaning.

    Examples
    --------
    >>> from dataclasses import replace
    >>> s = replace(RunSettings(), particles=5000, alphas=[0.1, 0.02, 0.05, 0.1])
    >>> s.particles, s.alphas
    (5000, (0.1, 0.02, 0.05, 0.1))
    >>> replace(s, injection=1)
    Traceback (most recent call last):
    ...
    ValueError: injection must be a fraction in [0, 1); got 1
    """

    particles: int | str = setting(
        "auto", "initial (with kld: largest) number of particles, or 'auto': one per KLD bin of the free space",
        check_particles, unit="particles", valid="whole number >= 1 or 'auto'", metavar="N",
        cli_help="""
        number of particles at the start, or 'auto' (default {default}): one per 0.5 m x 0.5 m x 10 degree
        cell of the pose space over the map's free space (KLD-sampling's cells), between 20,000 and 300,000
        -- about 75,000 for 520 m^2 of free floor, 115,000 for 800 m^2. With --kld (on by default) this is
        the initial and largest number: a dense uniform cloud, because with fewer particles most cells of
        the pose space are empty, and the filter then needs luck to have a particle near the robot.
        KLD-sampling shrinks the cloud to a few thousand once the filter agrees. Example: --particles
        100000""")
    sensor: str = setting(
        "likelihood", "sensor model: the likelihood field or the beam model (ray casting)",
        _choice("likelihood", "beam"), valid="likelihood or beam", choices=("likelihood", "beam"), cli_help="""
        sensor model: 'likelihood' field (fast, robust to small map errors) or the 'beam' model with ray
        casting (default {default}). Example: --sensor beam""")
    beams: int | None = setting(
        30, "evenly spread beams of each scan used (None: all)", _optional(check_count), unit="beams",
        valid="whole number >= 1", metavar="B", cli_help="""
        use B evenly spread beams of each scan (default {default}). Example: --beams 180""")
    max_range: float | None = setting(
        30.0, "sensor model's maximum range; longer readings are 'no return' (None: the log's)",
        _optional(_metres), unit="metres", valid="> 0", metavar="M", cli_help="""
        sensor model's maximum range in metres; longer readings count as 'no return' (default {default}).
        A log whose readings go beyond the range it states is read with the range they show, and the run says
        so; --max-range at or below the stated range keeps it. Example: --max-range 20""")
    alphas: tuple[float, float, float, float] = setting(
        (0.05, 0.01, 0.02, 0.05), "odometry noise alpha1..alpha4 of PR table 5.6 (variances)", _alphas,
        unit="variance factors", valid="four numbers >= 0", metavar=("A1", "A2", "A3", "A4"), nargs=4, cli_help="""
        odometry noise alpha1..alpha4 of Probabilistic Robotics table 5.6, as variances (default {default}).
        A step driven backwards is moved as a forward step of a robot facing the other way, and a step whose
        translation lies within the translation noise of a turn on the spot, sqrt(A3*t^2 + A4*turn^2), gets
        the noise of a turn on the spot (an odometry point off the robot's axis creeps sideways while it
        turns; taken as a drive, that step would turn almost 90 degrees and scatter the particles by half a
        metre). Example: --alphas 0.1 0.02 0.05 0.1""")
    sigma_hit: float = setting(
        0.2, "sensor noise: standard deviation of a beam about the map", _metres, unit="metres", valid="> 0",
        metavar="M", cli_help="""
        standard deviation of a beam's end point about the nearest wall (likelihood field) or of a reading
        about the ray-cast range (beam model), metres (default {default}): the map's error sets it, not the
        laser's (a few cm) -- real maps draw walls 0.1-0.15 m off and furniture moves.
        Example: --sigma-hit 0.3""")
    z_short: float = setting(
        0.2, "likelihood field: weight of short readings from unmapped obstacles", check_probability,
        unit="weight", valid="[0, 1]", metavar="W", cli_help="""
        likelihood field: weight in [0, 1] of short readings, beams stopped by something the map does not
        show (people, chairs, a door shut since the map was made) (default {default}). No returned beam then
        scores below W*lambda*exp(-lambda*z) + z_rand/max_range (lambda 0.5 per metre), so a short reading
        that ends in the map's free space counts as a likely unmapped obstacle, not as a miss that rules the
        true pose out. 0 scores the end points as Probabilistic Robotics table 6.3 does. Example:
        --z-short 0""")
    temper: float = setting(
        0.3, "factor on each scan's log-likelihood (neighbouring beams are not independent)", _unit,
        unit="factor", valid="(0, 1]", metavar="T", cli_help="""
        multiply each scan's log-likelihood by T in (0, 1] (default {default}): neighbouring beams see the
        same wall, so 30 beams are not 30 independent measurements, and an over-confident filter locks onto
        a wrong place. Example: --temper 0.1""")
    min_motion: tuple[float, float] = setting(
        (0.2, 0.3), "update only after moving this far or turning this much since the last update", _pair,
        unit="metres, radians", valid="two numbers >= 0", metavar=("M", "RAD"), nargs=2, cli_help="""
        weight the particles only after moving M metres or turning RAD radians since the last update, like
        ROS AMCL (default {default}; 0 0 updates at every scan). Example: --min-motion 0 0""")
    injection: float = setting(
        0.0, "fraction of random particles injected at each resampling", _fraction, unit="fraction",
        valid="[0, 1)", metavar="F", cli_help="""
        fraction in [0, 1) of random particles injected at each resampling (default {default}). Example:
        --injection 0.01""")
    min_range: float | None = setting(
        0.05, "readings at or below this range are not evidence (None or 0: none)", _optional(_metres0),
        unit="metres", valid=">= 0", metavar="M", cli_help="""
        readings at or below M metres are not evidence, like ROS AMCL's laser_min_range: lasers report 0 (or
        a few millimetres) for a failed reading, and nothing closer than the robot's own body is real
        (default {default}; likelihood field). Example: --min-range 0.1""")
    kld: float = setting(
        0.05, "KLD-sampling's bound epsilon (0: a fixed number of particles)", check_nonnegative,
        unit="KL divergence", valid=">= 0", metavar="EPS", cli_help="""
        KLD-sampling (Fox 2003): after each resampling keep only as many particles as a belief of this
        spread needs, with KL-divergence bound EPS; --particles is then the initial (and largest) number, so
        global localization starts with a dense cloud that shrinks once the filter agrees (default
        {default}; 0 keeps the number fixed). Example: --kld 0.1""")
    min_particles: int = setting(
        2000, "with kld: never fewer particles", check_count, unit="particles", valid="whole number >= 1",
        metavar="N", cli_help="""
        with --kld, never fewer than N particles (default {default}). Example: --min-particles 2000""")
    augmented: tuple[float, float] = setting(
        (0.0, 0.0), "augmented MCL's rates (alpha_slow, alpha_fast); 0 0: off", _pair, unit="rates",
        valid="two numbers >= 0", metavar=("SLOW", "FAST"), nargs=2, cli_help="""
        augmented MCL (Probabilistic Robotics table 8.3): inject random particles when the short-term
        average scan likelihood (rate FAST) drops below the long-term one (rate SLOW); 0 0 switches it off
        (default {default}). Example: --augmented 0.01 0.2""")
    recovery_injection: float = setting(
        0.0, "fraction of random particles injected at each resampling while lost", _fraction, unit="fraction",
        valid="[0, 1)", metavar="F", aliases=("--recovery",), cli_help="""
        while the state is 'lost', replace the fraction F of the particles by random ones at each
        resampling, so that the filter searches again (default {default}). Example: --recovery-injection 0""")
    restart_after: int = setting(
        5, "global localization again after this many updates in doubt of the place the cloud agreed on (0: never)",
        _count0, unit="updates", valid="whole number >= 0", metavar="K", cli_help="""
        start global localization again (all --particles drawn over the map beside the cloud, each half of the
        weight) when the cloud has agreed on one place but the filter has doubted it for K updates in a row:
        it is confidently wrong. Doubt is p_localized below 0.7 with the default --state probability, and
        scans that do not fit the map there with --state thresholds. Before the filter is first localized, a
        cloud gathered more loosely (within 2 m) counts too (with --state thresholds, so do updates at which
        the map cannot judge the scans at all, their beams ending in its unknown cells: a cloud stuck on such
        a place would otherwise search there for ever). A "lost" filter that stays in doubt for K updates
        restarts too. The
        old cloud and the new search then run side by side for up to 30 updates; the new one replaces the old
        place only if it wins both the sensor model's weight and the ray-cast fit of the scans, and fits them
        acceptably (default {default}; 0 never). Example: --restart-after 5""")
    sensor_reset: float = setting(
        0.0, "sensor resetting: while p_localized is low, draw up to this share of particles where the scan fits",
        _fraction, unit="fraction", valid="[0, 1)", metavar="F", cli_help="""
        sensor resetting (Lenser and Veloso 2000), with --state probability: at each update at which
        p_localized is below 0.7, the filter resamples and up to the share F of its particles is drawn near the
        places where the scan fits the map best (F times 1 - p_localized / 0.7: the more doubt, the more), each
        with the importance weight of a robot that may be anywhere (with probability 1 - p_localized), so a
        look-alike of the believed place is looked at, not made more probable; the next scans decide. An
        expert setting: beside --restart-after 0 it finds more robots on generated buildings, but not on the
        demo (default {default}; 0 never). Example: --sensor-reset 0.1 --restart-after 0""")
    min_ess: float = setting(
        0.0, "adaptive tempering: no update leaves fewer than min_ess * N effective particles (0: off)",
        check_nonnegative, unit="fraction of N", valid=">= 0", metavar="F", cli_help="""
        adaptive tempering: no single scan may leave fewer than F*N effective particles, so the first scans
        cannot collapse the cloud onto a look-alike place (default {default}; 0 off). Example: --min-ess 0.1""")
    expand: tuple[float, float] = setting(
        (0.0, 0.0), "expansion resetting's noise when the scans stop fitting an agreed cloud (0 0: never)", _pair,
        unit="metres, radians", valid="two numbers >= 0", metavar=("M", "RAD"), nargs=2, cli_help="""
        expansion resetting: when the cloud agrees on a place but the scan just used does not fit the map
        there, spread every particle by Gaussian noise of M metres and RAD radians, so that the next scans can
        find a robot that the odometry lost (wheel slip, a bump) (default {default}; 0 0 never). Example:
        --expand 0.2 0.1""")
    unknown_beams: str = setting(
        "skip", "beams ending in the map's unknown cells at an agreed place: skipped or scored",
        _choice("skip", "score"), valid="skip or score", choices=("skip", "score"), cli_help="""
        'skip': once the cloud agrees on one place, the beams whose end point there lies in a cell the map
        leaves unknown are left out of the update, and a scan with no other beam is not used; 'score': every
        beam is scored, an end point in an unknown cell with one neutral score (default {default}). The map
        cannot say whether such a beam fits, and scored it pulls the cloud of a robot that drives through a
        region the map left unknown towards that region's known walls. Example: --unknown-beams score""")
    skip_short_beams: float = setting(
        1.0, "at an agreed place, skip beams reading this much shorter than the map (0: score every beam)",
        _metres0, unit="metres", valid=">= 0", metavar="M", aliases=("--short-beams",), cli_help="""
        once the cloud agrees on one place, a beam that reads more than M metres shorter than the map's range
        from there is left out of the update: it hit something the map does not show (a person, a chair, a box
        in front of the mapped wall), and scored it lets a few particles at a wrong place, where its end point
        lies on some mapped wall, take the weight from the robot's cloud. If more than half of a scan reads
        short, every beam is scored: the place is then more likely wrong than cluttered (default {default}: twice
        the 0.5 m within which the cloud counts as agreed, more than its own error explains; 0 scores every
        beam). Example: --skip-short-beams 0""")
    state: str = setting(
        "probability", "where the searching/localized/lost state comes from: thresholds or probability",
        _choice("thresholds", "probability"), valid="thresholds or probability",
        choices=("thresholds", "probability"), cli_help="""
        'probability': the state comes from p_localized, the probability that the estimate is within 1 m of
        the robot (a Bayes filter over the scans' fit to the map, calibrated at start-up on this map and
        sensor model, weighed against look-alike places that the filter keeps as rivals and moves to when one
        fits 19 times better; localized at 0.95, lost below 0.7; restarts when it stays below 0.7; lost too
        when the particles' mass and the rivals' share alone no longer allow 0.95: p_place), both written
        to trajectory.csv and summary.json; 'thresholds': the fixed rules of localize.policies.StateRules,
        chosen on five logs, the default before stop 53 (default {default}; localize.reliability says what
        the probability still gets wrong). Example: --state thresholds""")
    occupied_penalty: float = setting(
        5.0, "log-likelihood a particle in an obstacle loses per update (inf: zero weight)", _penalty,
        unit="nats", valid="> 0 or inf", metavar="NATS", cli_help="""
        a particle standing in one of the map's obstacles loses NATS of log-likelihood at each update (default
        {default}: a pose in a wall is e^-5, about 150 times, less likely than one in free space with the same
        scan fit); 'inf' gives it zero weight. Finite, a robot that drives through an obstacle the map is wrong
        about (a door drawn shut, furniture since moved, walls drawn too thick) keeps its cloud: every particle
        in it pays the same, and the scans decide. Outside the map a particle has zero weight either way.
        Example: --occupied-penalty inf""")
    odometry_sign: str = setting(
        "auto", "when the scans may reverse odometry steps: auto, check or trust",
        _choice("auto", "check", "trust"), valid="auto, check or trust", choices=("auto", "check", "trust"),
        cli_help="""
        'check': compare every odometry step of at least 5 cm with the two scans around it, and drive
        backwards the steps whose reverse fits the scans clearly better (the second scan's end points, placed
        with the step reversed, lie within 70 percent of the distance they lie at with the step as logged); 'auto'
        (default {default}): check only odometry that never reports reversing, a speed without a sign that
        records every backing-up as driving forwards (the Freiburg 079 log's does); 'trust': never.
        summary.json lists the steps reversed. Example: --odometry-sign trust""")
    track: bool = setting(
        False, "pose tracking: start around the log's first reference pose instead of everywhere", _flag,
        valid="True or False", cli_help="""
        pose tracking instead of global localization: start around the log's first reference pose (needs a
        corrected log).""")
    initial_pose: tuple[float, float, float] | None = setting(
        None, "a known start: particles drawn around this pose (x, y in the map frame, yaw) instead of everywhere",
        _optional(_pose3), unit="metres, metres, radians", valid="three numbers", metavar=("X", "Y", "YAW"), nargs=3,
        cli_help="""start around this pose, map frame, metres and radians (default: none, global localization). Example: --initial-pose 2 3.5 1.57""")
    initial_std: tuple[float, float, float] = setting(
        (0.5, 0.5, 0.2618), "with initial_pose: standard deviations of the start's Gaussian (AMCL's defaults)",
        _std3, unit="metres, metres, radians", valid="three numbers > 0", metavar=("SX", "SY", "SYAW"), nargs=3,
        cli_help="""with --initial-pose: its standard deviations (default {default}, AMCL's initial_cov_*). Example: --initial-std 0.3 0.3 0.2""")
    # ---------------------------------------------------------------- library settings (no flag)
    init_std: tuple[float, float, float] = setting(
        (0.1, 0.1, 0.05), "with track: standard deviations of the prior around the first reference pose", _std3,
        unit="metres, metres, radians", valid="three numbers > 0", flag=False)
    resample_threshold: float = setting(
        0.5, "resample when N_eff < threshold * N (1: after every update)", check_probability,
        unit="fraction of N", valid="[0, 1]", flag=False)
    kld_delta: float = setting(
        0.01, "with kld: KLD-sampling's delta (1 - confidence)", _open_unit, valid="(0, 1)", flag=False)
    kld_max_particles: int | None = setting(
        None, "with kld: the largest number of particles (None: particles)", _optional(check_count),
        unit="particles", valid="whole number >= 1", flag=False)
    kld_chunked: bool = setting(
        True, "with kld: draw in chunks (localize run) or one particle at a time (AMCL)", _flag, flag=False)
    augmented_temperature: float | None = setting(
        None, "augmented MCL: log-likelihoods divided by this (None: the number of beams)",
        _optional(check_positive), valid="> 0", flag=False)
    sensor_params: dict = setting(
        {}, "more keyword arguments of the sensor model (z_hit, z_rand, max_dist, method ...)", _params,
        flag=False)
    free_space_only: bool = setting(
        True, "particles leaving the map's free cells get zero weight", _flag, flag=False)
    unknown_allowed: bool = setting(
        True, "with free_space_only: particles may stand in unknown cells", _flag, flag=False)
    unknown_penalty: float = setting(
        0.0, "log-likelihood a particle in an unknown cell loses per update", check_nonnegative, unit="nats",
        valid=">= 0", flag=False)
    odometry_outliers: float = setting(
        0.0, "share of particles moved by an odometry outlier at each step (0: plain model)", _fraction,
        unit="fraction", valid="[0, 1)", flag=False)
    min_trans: float = setting(
        1e-3, "odometry steps shorter than this are turns on the spot", _metres0, unit="metres", valid=">= 0",
        flag=False)

    def __post_init__(self) -> None:
        for f in fields(self):
            object.__setattr__(self, f.name, f.metadata["check"](getattr(self, f.name), f.name))
        lo, hi = self.min_range, self.max_range
        if lo is not None and hi is not None and not lo < hi:
            raise ValueError(f"min_range (--min-range) {lo:g} m must be below max_range (--max-range) {hi:g} m: "
                             "readings between the two are the scan's evidence")
        if self.sensor_reset > 0 and self.state != "probability":
            raise ValueError(f"sensor_reset (--sensor-reset) {self.sensor_reset:g} needs state (--state) probability, "
                             f"not {self.state}: it draws particles while p_localized is low")

    def summary(self) -> dict:
        """The command-line settings (flag order) as ``summary.json`` lists them: tuples as lists.

        >>> list(RunSettings().summary())[:3], RunSettings().summary()["alphas"]
        (['particles', 'sensor', 'beams'], [0.05, 0.01, 0.02, 0.05])
        """
        return {f.name: jsonable(getattr(self, f.name)) for f in fields(self)
                if f.metadata["flag"] and f.name != "track"}


def jsonable(v: Any) -> Any:
    """``v`` as JSON holds it: tuples and lists as lists, other objects as their text.

    >>> jsonable((0.2, (1, 2), None))
    [0.2, [1, 2], None]
    """
    if isinstance(v, (tuple, list)):
        return [jsonable(x) for x in v]
    return v if isinstance(v, (int, float, str, bool)) or v is None else str(v)


#: Each setting's default, by name.
DEFAULTS: dict[str, Any] = {f.name: (f.default if f.default is not MISSING else f.default_factory())
                            for f in fields(RunSettings)}

#: Names the settings had before they had one (``localize_log``'s keywords, ``cli.DEFAULTS``' keys):
#: still accepted by :func:`localize.pipeline.localize_log`.
LEGACY_NAMES: dict[str, str] = {"n_particles": "particles", "short_beams": "skip_short_beams",
                                "recovery": "recovery_injection"}


def setting_names(cli_only: bool = False) -> tuple[str, ...]:
    """The names of the settings (``cli_only``: those with a command-line flag).

    >>> setting_names(cli_only=True)[-3:]
    ('track', 'initial_pose', 'initial_std')
    """
    return tuple(f.name for f in fields(RunSettings) if f.metadata["flag"] or not cli_only)


def describe(name: str) -> str:
    """One line on a setting: name, unit, valid range, default and help.

    >>> describe("recovery_injection")
    'recovery_injection (fraction, [0, 1), default 0): fraction of random particles injected at each resampling while lost'
    """
    by_name = {f.name: f for f in fields(RunSettings)}
    if name not in by_name:
        raise ValueError(f"no setting {name!r}; the settings are {', '.join(by_name)}")
    f = by_name[name]
    m = f.metadata
    what = ", ".join(x for x in (m["unit"], m["valid"], f"default {_shown(DEFAULTS[name])}") if x)
    return f"{name} ({what}): {m['help']}"


def _shown(value: Any) -> str:
    """A default as ``--help`` shows it: numbers by ``:g``, the values of a tuple separated by spaces."""
    if isinstance(value, (tuple, list)):
        return " ".join(_shown(v) for v in value)
    return f"{value:g}" if isinstance(value, float) else str(value)


# ============================================================================ the command line
def argparse_type(check: Callable[[Any, str], Any], name: str) -> Callable[[str], Any]:
    """An argparse ``type`` running ``check(text, name)``; its message is the check's, "NAME must be" read "expected".

    >>> parse = argparse_type(check_positive, "sigma_hit")
    >>> parse("0.3")
    0.3
    >>> parse("0")
    Traceback (most recent call last):
    ...
    argparse.ArgumentTypeError: expected a finite number > 0; got '0'
    """

    def parse(text: str) -> Any:
        try:
            return check(text, name)
        except (TypeError, ValueError) as exc:
            msg = str(exc).replace(" must be finite;", " must be a finite number;")
            prefix = f"{name} must be "
            raise argparse.ArgumentTypeError("expected " + msg[len(prefix):] if msg.startswith(prefix) else msg
                                             ) from None

    parse.__name__ = name
    return parse


def _element_check(f: Any) -> Callable[[Any, str], Any]:
    """The check of one value of a setting that takes several on the command line."""
    if f.name == "alphas":
        return check_nonnegative
    if f.name == "initial_pose":
        return check_number
    if f.name == "initial_std":
        return check_positive
    return check_nonnegative if f.metadata["nargs"] else f.metadata["check"]


#: The ``localize run --help`` line of each setting with a flag: its group and its one-line meaning (the
#: default is appended). The rationale behind each is :func:`explain`'s (and chapter 9's).
CLI_GROUPS: dict[str, tuple[str, str]] = {
    "particles": ("filter", "start cloud; auto: by free area"),
    "sensor": ("sensor", "likelihood or beam"),
    "beams": ("sensor", "beams used per scan"),
    "max_range": ("sensor", "longest usable reading, m"),
    "alphas": ("filter", "odometry noise"),
    "sigma_hit": ("sensor", "reading's spread about the map, m"),
    "z_short": ("sensor", "weight of short (unmapped) readings"),
    "temper": ("sensor", "factor on a scan's log-likelihood"),
    "min_motion": ("filter", "update after M m or RAD turned"),
    "injection": ("recovery", "random particles per resampling"),
    "min_range": ("sensor", "readings up to M m are ignored"),
    "kld": ("filter", "KLD-sampling bound (0: fixed count)"),
    "min_particles": ("filter", "with --kld: never fewer particles"),
    "augmented": ("recovery", "augmented MCL rates (0 0: off)"),
    "recovery_injection": ("recovery", "while lost: random particles"),
    "restart_after": ("recovery", "search again after K updates in doubt (0: no)"),
    "sensor_reset": ("recovery", "while in doubt: draw where the scan fits"),
    "min_ess": ("filter", "keep F*N effective particles (0: off)"),
    "expand": ("recovery", "spread the cloud on misfit"),
    "unknown_beams": ("sensor", "unknown-cell beams: skip, score"),
    "skip_short_beams": ("sensor", "skip beams M m short of the map"),
    "occupied_penalty": ("sensor", "penalty of a particle in a wall"),
    "state": ("recovery", "state from thresholds or probability"),
    "odometry_sign": ("filter", "find reversing: auto, check, trust"),
    "track": ("filter", "start at the log's first true pose"),
    "initial_pose": ("filter", "start around this pose, m and rad"),
    "initial_std": ("filter", "--initial-pose's spread"),
}


def explain(name: str) -> str:
    """A setting's longer explanation: what it does and why its default (what ``--help`` leaves out).

    >>> explain("temper").endswith("so 30 beams are not 30 independent measurements, and an over-confident "
    ...                            "filter locks onto a wrong place.")
    True
    """
    by_name = {f.name: f for f in fields(RunSettings)}
    if name not in by_name:
        raise ValueError(f"no setting {name!r}; the settings are {', '.join(by_name)}")
    f = by_name[name]
    text = " ".join(f.metadata["cli_help"].split()).format(default=_shown(f.default))
    return text.split(" Example: ")[0].rstrip()


def _default_text(f: Any) -> str:
    if isinstance(f.default, bool):
        return "default off"
    if f.default is None:
        return "default none"
    return f"default {_shown(f.default)}"


def add_arguments(parser: Any, groups: Mapping[str, Any] | None = None) -> None:
    """Add one option per setting with a flag to ``parser`` (an argparse parser or argument group), or to
    ``groups[name]`` by the setting's group in :data:`CLI_GROUPS` (sensor, filter, recovery).

    The option's destination is the setting's name; its default is the setting's
    default, and its help the one line of :data:`CLI_GROUPS` with the default;
    old flags (``--recovery``, ``--short-beams``) are aliases (not listed).

    >>> ap = argparse.ArgumentParser()
    >>> add_arguments(ap)
    >>> ap.parse_args(["--short-beams", "0"]).skip_short_beams
    0.0
    >>> "--short-beams" in ap.format_help(), "(default 1)" in ap.format_help()
    (False, True)
    """
    for f in fields(RunSettings):
        m = f.metadata
        if not m["flag"]:
            continue
        group, brief = CLI_GROUPS.get(f.name, ("filter", m["help"]))
        target = parser if groups is None else groups[group]
        text = f"{brief} ({_default_text(f)})"
        names = ["--" + f.name.replace("_", "-")]
        if isinstance(f.default, bool):
            target.add_argument(*names, dest=f.name, action="store_true", help=text)
            continue
        kw: dict[str, Any] = {k: m[k] for k in ("nargs", "metavar", "choices") if m[k] is not None}
        if m["choices"] is None:
            kw["type"] = argparse_type(_element_check(f), f.name)
        else:
            kw.setdefault("metavar", "WHICH")  # the choices are in the help line
        for alias in m["aliases"]:  # before the flag: the flag's action is the setting's last one
            target.add_argument(alias, dest=f.name, default=f.default, help=argparse.SUPPRESS, **kw)
        target.add_argument(*names, dest=f.name, default=f.default, help=text, **kw)


def from_namespace(args: argparse.Namespace, **changes: Any) -> RunSettings:
    """The :class:`RunSettings` of parsed arguments (``args`` is read, never changed), with ``changes``.

    >>> ap = argparse.ArgumentParser()
    >>> add_arguments(ap)
    >>> from_namespace(ap.parse_args(["--beams", "60", "--track"])).beams
    60
    """
    values = {n: getattr(args, n) for n in setting_names(cli_only=True) if hasattr(args, n)}
    return RunSettings(**{**values, **changes})


def parse_options(argv: list[str] | tuple[str, ...] = ()) -> RunSettings:
    """The :class:`RunSettings` that ``localize run``'s filter options ``argv`` stand for (the benchmarks' way to
    run exactly what the command line runs).

    >>> parse_options(["--kld", "0", "--short-beams", "0.5"]).skip_short_beams
    0.5
    """
    ap = argparse.ArgumentParser(prog="localize run", add_help=False)
    add_arguments(ap)
    return from_namespace(ap.parse_args(list(argv)))


def given_options(option_dests: Mapping[str, str], argv: list[str] | tuple[str, ...]) -> set[str]:
    """Destinations of the options written in ``argv`` (unique prefixes count, as in argparse).

    >>> sorted(given_options({"--beams": "beams", "--beam-x": "x", "--temper": "temper"}, ["--temp", "0.5", "--b"]))
    ['temper']
    """
    given = set()
    for tok in argv:
        if tok == "--":
            break
        if not tok.startswith("--"):
            continue
        name = tok.split("=", 1)[0]
        if name in option_dests:
            given.add(option_dests[name])
            continue
        hits = {d for o, d in option_dests.items() if o.startswith(name)}
        if len(hits) == 1:
            given |= hits
    return given


# ============================================================================ ROS AMCL parameter files
#: The settings an AMCL parameter file gives (:func:`localize.amcl.read_amcl_params`'s ``settings``), by name.
AMCL_SETTINGS = ("particles", "alphas", "sensor", "beams", "max_range", "min_range", "sigma_hit", "min_motion")


def with_amcl(settings: RunSettings, amcl: Mapping[str, Any], given: set[str] = frozenset()) -> tuple[RunSettings,
                                                                                                        list[str]]:
    """``settings`` with what an AMCL parameter file says (``amcl``: :class:`localize.amcl.AmclMapping`'s
    ``settings``); settings in ``given`` (written on the command line) win. Returns the new settings and the
    names of the settings kept.

    AMCL's likelihood field has no short-reading term: ``z_short`` becomes 0
    unless given. The sensor model's mixture weights (``sensor_params``) apply
    when the sensor is the file's; KLD-sampling (unchunked, AMCL's bounds and
    delta), augmented MCL (temperature 1) and the resampling threshold are the
    file's. A file whose ``min_particles`` equals its ``max_particles`` (AMCL:
    no KLD-sampling) leaves ``kld`` as it was.

    Examples
    --------
    >>> from localize.amcl import amcl_settings
    >>> m = amcl_settings({"kld_err": 0.05, "kld_z": 0.99, "min_particles": 500, "max_particles": 2000})
    >>> s, kept = with_amcl(RunSettings(), m.settings, given={"beams"})
    >>> s.particles, s.min_particles, s.kld_max_particles, s.z_short, s.beams, kept
    (2000, 500, 2000, 0.0, 30, ['beams'])
    """
    kept = [n for n in AMCL_SETTINGS if n in given]
    ch: dict[str, Any] = {n: amcl[n] for n in AMCL_SETTINGS if n not in given}
    if "z_short" in given:
        kept.append("z_short")
    else:
        ch["z_short"] = 0.0
    sensor = ch.get("sensor", settings.sensor)
    if sensor == amcl["sensor"]:
        ch["sensor_params"] = {**amcl["sensor_params"], **settings.sensor_params}
    kld = amcl["kld"]
    if kld is not None:
        ch.update(kld=kld.epsilon, kld_delta=kld.delta, min_particles=kld.n_min, kld_max_particles=kld.n_max,
                  kld_chunked=kld.chunked)
    aug = amcl["augmented"]
    if aug is not None:
        ch.update(augmented=(aug.alpha_slow, aug.alpha_fast), augmented_temperature=aug.temperature)
    ch["resample_threshold"] = amcl["resample_threshold"]
    if amcl.get("initial_pose") is not None:  # AMCL's initial_pose_* / initial_cov_*: a known start
        for n in ("initial_pose", "initial_std"):
            if n in given:
                kept.append(n)
            else:
                ch[n] = amcl[n]
    return replace(settings, **ch), kept
