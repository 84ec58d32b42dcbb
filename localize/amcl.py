"""ROS AMCL parameter files as ``localize`` settings (ROS 1 ``amcl`` and nav2 ``nav2_amcl``).

:func:`read_amcl_params` reads the YAML a robot already runs AMCL with and maps
each parameter that has a counterpart here, with AMCL's own conventions; every
other parameter is listed with the reason it is ignored. The two dialects name
the same things differently (ROS 1 ``odom_alpha1``, ``laser_z_hit``,
``laser_max_beams``, ``kld_err``/``kld_z``; nav2 ``alpha1``, ``z_hit``,
``max_beams``, ``pf_err``/``pf_z``); both are understood, and missing
parameters take the default of the dialect the file is written in, as AMCL
would.

The conventions that trip people up:

* **Odometry alphas.** nav2's differential model and ROS 1's ``diff-corrected``
  draw each noise with the standard deviation ``sqrt(alpha1*rot**2 +
  alpha2*trans**2)`` -- Probabilistic Robotics table 5.6 with variances, as
  here. ROS 1's ``diff`` and ``omni`` models (``diff`` is ROS 1's default) pass
  the expression *without* the square root, so the alphas there are in
  different units; they are converted term by term at one filter step
  (``update_min_d``, ``update_min_a``). ROS 1's omni models also use alpha1
  where the documentation says alpha4 and vice versa (ros-planning/navigation
  issue 542); the swap is undone. alpha5 (omni strafe noise) has no
  counterpart: ``localize`` has the differential-drive model only.
* **pf_z / kld_z is the quantile** ``z_{1-delta}`` of KLD-sampling, not a
  probability: the default 0.99 means ``delta = 1 - Phi(0.99) = 0.16``, not 0.01.
* **The beams' likelihoods are combined differently.** AMCL scores a scan as
  ``1 + sum(p_beam**3)``, an ad-hoc cure for correlated beams; ``localize``
  multiplies the beams' likelihoods and tempers the product (``--temper``),
  so ``temper`` stays a ``localize`` setting. Mixture weights are normalised
  to sum to 1 (a common factor cancels from the particle weights).
* ``laser_min_range``/``laser_max_range`` of -1 mean "the scan's own";
  readings below the minimum count as no return (AMCL sets them to the maximum).
* ``resample_interval: 1`` (resample after every update) is
  ``resample_threshold = 1``; ROS 1's ``selective_resampling: true`` resamples
  when ``N_eff < N/2``, which is ``resample_threshold = 0.5``. Larger intervals
  have no counterpart.

The mapping table (:data:`MAPPING_TABLE`) is printed by ``localize run --help``
and shown in chapter 9.
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .io._common import FormatError
from .io._yaml import load_yaml
from .kld import KLDSampling
from .mcl import Augmented

__all__ = ["read_amcl_params", "amcl_settings", "AmclMapping", "MAPPING_TABLE", "NAV2_DEFAULTS", "ROS1_DEFAULTS",
           "ROS1_NAMES"]

PathLike = str | os.PathLike

#: ROS 1 parameter names and their nav2 names (the canonical names used here).
ROS1_NAMES = {
    **{f"odom_alpha{i}": f"alpha{i}" for i in range(1, 6)},
    "odom_model_type": "robot_model_type",
    "laser_max_beams": "max_beams",
    "laser_z_hit": "z_hit", "laser_z_short": "z_short", "laser_z_max": "z_max", "laser_z_rand": "z_rand",
    "laser_sigma_hit": "sigma_hit", "laser_lambda_short": "lambda_short",
    "kld_err": "pf_err", "kld_z": "pf_z",
}

#: Defaults of nav2_amcl (docs.nav2.org, "AMCL"; nav2_bringup/params/nav2_params.yaml).
NAV2_DEFAULTS: dict[str, Any] = {
    "alpha1": 0.2, "alpha2": 0.2, "alpha3": 0.2, "alpha4": 0.2, "alpha5": 0.2,
    "robot_model_type": "nav2_amcl::DifferentialMotionModel",
    "laser_model_type": "likelihood_field", "max_beams": 60, "laser_min_range": -1.0, "laser_max_range": 100.0,
    "z_hit": 0.5, "z_short": 0.05, "z_max": 0.05, "z_rand": 0.5, "sigma_hit": 0.2, "lambda_short": 0.1,
    "laser_likelihood_max_dist": 2.0, "min_particles": 500, "max_particles": 2000, "pf_err": 0.05, "pf_z": 0.99,
    "recovery_alpha_slow": 0.0, "recovery_alpha_fast": 0.0, "update_min_d": 0.25, "update_min_a": 0.2,
    "resample_interval": 1,
}

#: Defaults of ROS 1 amcl (wiki.ros.org/amcl), in nav2 names.
ROS1_DEFAULTS: dict[str, Any] = {
    "alpha1": 0.2, "alpha2": 0.2, "alpha3": 0.2, "alpha4": 0.2, "alpha5": 0.2, "robot_model_type": "diff",
    "laser_model_type": "likelihood_field", "max_beams": 30, "laser_min_range": -1.0, "laser_max_range": -1.0,
    "z_hit": 0.95, "z_short": 0.1, "z_max": 0.05, "z_rand": 0.05, "sigma_hit": 0.2, "lambda_short": 0.1,
    "laser_likelihood_max_dist": 2.0, "min_particles": 100, "max_particles": 5000, "pf_err": 0.01, "pf_z": 0.99,
    "recovery_alpha_slow": 0.0, "recovery_alpha_fast": 0.0, "update_min_d": 0.2, "update_min_a": math.pi / 6,
    "resample_interval": 2,
}

_IGNORED = {
    "ROS interface (frames, topics, tf, timing): nothing to do in an offline run": (
        "base_frame_id", "odom_frame_id", "global_frame_id", "scan_topic", "map_topic", "tf_broadcast",
        "transform_tolerance", "save_pose_rate", "gui_publish_rate", "use_map_topic", "first_map_only",
        "use_sim_time", "introspection_mode", "bond_heartbeat_period", "map_subscribe_transient_local",
        "receive_map_topic", "restore_defaults", "service_introspection_mode", "bond_disable_heartbeat_timeout",
        "freespace_downsampling"),
    "initial pose: not set (nav2: set_initial_pose is false), so localize run localizes globally": (
        "set_initial_pose", "always_reset_initial_pose", "initial_pose", "initial_pose_x", "initial_pose_y",
        "initial_pose_a", "initial_cov_xx", "initial_cov_yy", "initial_cov_aa"),
    "beam skipping is not implemented in localize (--short-beams and --unknown-beams leave beams out by other rules)": (
        "do_beamskip", "beam_skip_distance", "beam_skip_threshold", "beam_skip_error_threshold"),
    "the seed is --seed": ("random_seed",),
}

#: The mapping, as printed by ``localize run --help``.
MAPPING_TABLE = """\
AMCL parameter (nav2 / ROS 1)              localize setting
alpha1..alpha4 / odom_alpha1..4            --alphas (PR table 5.6, variances; ROS 1 'diff'/'omni' converted,
                                             ROS 1 omni's alpha1/alpha4 swap undone)
alpha5 / odom_alpha5                       ignored (omni strafe noise; differential model only)
robot_model_type / odom_model_type         how the alphas are read (see above)
laser_model_type                           --sensor: likelihood_field -> likelihood, beam -> beam,
                                             likelihood_field_prob -> likelihood (no beam skipping)
max_beams / laser_max_beams                --beams
laser_min_range                            readings below it are 'no return' (-1: the scan's range_min)
laser_max_range                            --max-range (-1: the scan's range_max)
z_hit, z_rand (/ laser_z_*)                likelihood/beam mixture weights, normalised to sum 1
z_short, z_max, lambda_short               beam model only (ignored by the likelihood field, as in AMCL)
sigma_hit / laser_sigma_hit                --sigma-hit
laser_likelihood_max_dist                  likelihood field max_dist (distance cap)
min_particles, max_particles               --particles = max_particles; KLD-sampling between the two
pf_err, pf_z / kld_err, kld_z              KLD epsilon = pf_err, delta = 1 - Phi(pf_z) (pf_z is the quantile)
recovery_alpha_slow, recovery_alpha_fast   augmented MCL (alpha_slow, alpha_fast); 0, 0: off
update_min_d, update_min_a                 --min-motion
resample_interval                          1: resample after every update (resample_threshold 1);
                                             >1: no counterpart (N_eff < N/2 is used)
selective_resampling (ROS 1)               true: resample_threshold 0.5
initial_pose / initial_pose_x, _y, _a      --initial-pose (nav2: with set_initial_pose true)
initial_cov_xx, _yy, _aa                   --initial-std: their square roots (defaults 0.25, 0.25, 0.0685)
frames, topics, tf, beam skipping, random_seed: ignored, each with a warning
(--temper and --seed stay localize settings; options given on the command line win over the file)"""


@dataclass
class AmclMapping:
    """The result of reading an AMCL parameter file.

    Attributes
    ----------
    settings : dict
        ``localize`` settings by command-line name (``particles``, ``alphas``,
        ``sensor``, ``beams``, ``max_range``, ``min_range``, ``sigma_hit``,
        ``min_motion``) and filter options (``sensor_params``,
        ``resample_threshold``, ``kld``, ``augmented``).
    rows : list of (parameter, value, setting, note)
        What was mapped, for printing.
    ignored : list of (parameter, value, reason)
        Parameters without a counterpart.
    dialect : {"nav2", "ros1"}
    source : str
    """

    settings: dict = field(default_factory=dict)
    rows: list = field(default_factory=list)
    ignored: list = field(default_factory=list)
    dialect: str = "nav2"
    source: str = "<dict>"

    def table(self) -> str:
        """The mapping used, one line per localize setting."""
        lines = [f"AMCL parameters from {self.source} ({self.dialect} dialect):"]
        for name, value, setting, note in self.rows:
            left = f"{name} = {_fmt(value)}"
            right = f"-> {setting}" + (f"  ({note})" if note else "")
            lines.append(f"  {left:<44} {right}" if len(left) <= 44 else f"  {left}\n  {'':<44} {right}")
        return "\n".join(lines)

    def warnings(self) -> list[str]:
        """One line per ignored parameter."""
        return [f"{self.source}: ignoring AMCL parameter {name} = {_fmt(value)}: {reason}"
                for name, value, reason in self.ignored]


def _fmt(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:g}"
    if isinstance(v, (list, tuple)):
        return "(" + ", ".join(_fmt(x) for x in v) + ")"
    return str(v)


def _load_yaml(path: Path) -> Any:
    """The file's YAML (PyYAML); a key given twice is refused with its line, as ROS refuses the file."""
    return load_yaml(path)


def _find_params(doc: Any) -> tuple[dict, bool]:
    """The flat dict of AMCL parameters inside a ROS 1 or nav2 YAML document."""
    nav2 = False
    if not isinstance(doc, dict):
        return {}, nav2
    for _ in range(3):
        if "amcl" in doc and isinstance(doc["amcl"], dict):
            doc = doc["amcl"]
        elif "/amcl" in doc and isinstance(doc["/amcl"], dict):
            doc = doc["/amcl"]
        if "ros__parameters" in doc and isinstance(doc["ros__parameters"], dict):
            doc, nav2 = doc["ros__parameters"], True
    return doc, nav2


def read_amcl_params(path: PathLike) -> AmclMapping:
    """Read a ROS 1 ``amcl`` or nav2 ``nav2_amcl`` parameter YAML and map it to localize settings.

    The file may be a nav2 parameter file (``amcl: ros__parameters: ...``, other
    nodes' sections are skipped), a ROS 1 ``rosparam`` file (flat, or under an
    ``amcl:`` namespace). See the module docstring for the conventions.

    Raises
    ------
    FormatError
        The file is missing, not YAML, holds no AMCL parameter, or a value is
        of the wrong kind or out of range (the message names the parameter
        and its line).

    Examples
    --------
    >>> p = tmp_text("amcl.yaml", "amcl:\\n  ros__parameters:\\n    max_particles: 3000\\n    min_particles: 3000\\n"
    ...              "    base_frame_id: base_link\\n")
    >>> m = read_amcl_params(p)
    >>> m.settings["particles"], m.settings["kld"]
    (3000, None)
    >>> m.ignored[0][0]
    'base_frame_id'
    """
    p = Path(path)
    if not p.is_file():
        raise FormatError(p, None, "no such file (expected an AMCL parameter YAML)")
    params, nav2 = _find_params(_load_yaml(p))
    text = p.read_text().splitlines()
    return amcl_settings(params, source=str(p), nav2=nav2 or None, lines=text)


class _Params:
    """The parameters of one AMCL file in canonical (nav2) names, with the file's names, lines and defaults."""

    def __init__(self, params: dict, source: str, nav2: bool | None, lines: list[str] | None) -> None:
        self.source, self.lines = source, lines
        self.orig = {str(k): v for k, v in params.items()}
        self.names: dict[str, str] = {}  # canonical -> name in the file
        self.vals: dict[str, Any] = {}
        ros1_hits = 0
        for k, v in self.orig.items():
            c = ROS1_NAMES.get(k, k)
            ros1_hits += k in ROS1_NAMES
            if c in self.names and self.names[c] != k:
                raise FormatError(source, self.where(k), f"{k} and {self.names[c]} set the same AMCL parameter; "
                                                         "keep one")
            self.names[c], self.vals[c] = k, v
        known = set(NAV2_DEFAULTS) | {"selective_resampling"} | {n for ns in _IGNORED.values() for n in ns}
        if not (set(self.vals) & known):
            raise FormatError(source, None, "no AMCL parameters found: expected keys such as alpha1 / odom_alpha1, "
                                            f"max_particles, laser_model_type; got {', '.join(sorted(self.orig))}")
        self.nav2 = ros1_hits == 0 if nav2 is None else nav2
        self.defaults = NAV2_DEFAULTS if self.nav2 else ROS1_DEFAULTS
        self.used: set[str] = set()
        self._ros1_name = {v: k for k, v in ROS1_NAMES.items()}

    def where(self, name: str) -> int | None:
        """The line of ``name: ...`` in the file (None without the file's lines)."""
        if self.lines:
            pat = re.compile(rf"^\s*{re.escape(name)}\s*:")
            for n, s in enumerate(self.lines, start=1):
                if pat.match(s):
                    return n
        return None

    def error(self, c: str, message: str) -> FormatError:
        return FormatError(self.source, self.where(self.label(c)), message)

    def get(self, c: str) -> Any:
        self.used.add(c)
        return self.vals.get(c, self.defaults[c])

    def label(self, c: str) -> str:
        """The parameter's name in the file, or its name in the file's dialect with ``(default)``."""
        return self.names.get(c) or (c if self.nav2 else self._ros1_name.get(c, c)) + " (default)"

    def num(self, c: str, lo: float | None = None, hi: float | None = None, integer: bool = False) -> float:
        v = self.get(c)
        name = self.names.get(c, c)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(float(v)):
            raise FormatError(self.source, self.where(name), f"{name} must be a number; got {v!r}")
        if integer and float(v) != int(v):
            raise FormatError(self.source, self.where(name), f"{name} must be a whole number; got {v!r}")
        v = float(v)
        if (lo is not None and v < lo) or (hi is not None and v > hi):
            rng_txt = f"[{lo if lo is not None else '-inf'}, {hi if hi is not None else 'inf'}]"
            raise FormatError(self.source, self.where(name), f"{name} must lie in {rng_txt}; got {v:g}")
        return int(v) if integer else v

    def ignore_if_given(self, m: "AmclMapping", c: str, reason: str) -> None:
        self.used.add(c)
        if c in self.vals:
            m.ignored.append((self.names[c], self.vals[c], reason))


_MOTION_MODELS = ("diff", "diff-corrected", "omni", "omni-corrected", "differential", "omnidirectional",
                  "nav2_amcl::differentialmotionmodel", "nav2_amcl::omnimotionmodel")


def _motion(p: _Params, m: AmclMapping) -> tuple[float, float]:
    """Odometry alphas (PR variances) from the file's model; returns update_min_d, update_min_a."""
    mt = str(p.get("robot_model_type"))
    mt_l = mt.lower()
    omni = "omni" in mt_l
    if mt_l not in _MOTION_MODELS:
        raise p.error("robot_model_type", f"{p.label('robot_model_type')}: unknown motion model {mt!r}; expected "
                      "diff, diff-corrected, omni, omni-corrected (ROS 1) or nav2_amcl::DifferentialMotionModel / "
                      "nav2_amcl::OmniMotionModel (nav2)")
    a = [p.num(f"alpha{i}", lo=0.0) for i in range(1, 5)]
    d_ref, a_ref = p.num("update_min_d", lo=0.0), p.num("update_min_a", lo=0.0)
    note = "as variances, PR table 5.6 (AMCL draws with sqrt of the same sums)"
    if mt_l in ("omni", "omni-corrected"):  # ROS 1 omni: code uses alpha1 <-> alpha4 against the docs
        a = [a[3], a[1], a[2], a[0]]
        note = "ROS 1 omni model: alpha1 and alpha4 swapped back (navigation issue 542)"
    if mt_l in ("diff", "omni"):  # ROS 1 uncorrected: the sums are standard deviations
        dr, ar = max(d_ref, 0.05), max(a_ref, 0.05)
        a = [a[0] ** 2 * ar**2, a[1] ** 2 * dr**2, a[2] ** 2 * dr**2, a[3] ** 2 * ar**2]
        note = (f"ROS 1 '{mt}' model draws with std = alpha*x**2 (no sqrt): converted term by term to PR variances "
                f"at one step of {dr:g} m / {ar:g} rad" + (", alpha1/alpha4 swap undone" if omni else ""))
    m.settings["alphas"] = tuple(round(x, 9) for x in a)
    m.rows.append((", ".join(p.label(f"alpha{i}") for i in range(1, 5)) + f" [{p.label('robot_model_type')}={mt}]",
                   tuple(p.get(f"alpha{i}") for i in range(1, 5)), f"alphas = {_fmt(m.settings['alphas'])}", note))
    if omni:
        m.ignored.append((p.label("alpha5"), p.get("alpha5"), "omni strafe noise: localize has the differential-"
                                                               "drive odometry model only"))
    elif "alpha5" in p.vals:
        m.ignored.append((p.names["alpha5"], p.vals["alpha5"], "used by the omni model only (as in AMCL)"))
    p.used.add("alpha5")
    return d_ref, a_ref


def _laser(p: _Params, m: AmclMapping) -> str:
    """Sensor model, beams and ranges; returns the sensor."""
    s, rows = m.settings, m.rows
    lm = str(p.get("laser_model_type"))
    if lm not in ("likelihood_field", "beam", "likelihood_field_prob"):
        raise FormatError(p.source, p.where("laser_model_type"), f"laser_model_type: unknown model {lm!r}; expected "
                                                                 "likelihood_field, beam or likelihood_field_prob")
    sensor = "beam" if lm == "beam" else "likelihood"
    s["sensor"] = sensor
    rows.append((p.label("laser_model_type"), lm, f"sensor = {sensor}",
                 "beam skipping of likelihood_field_prob is not implemented" if lm == "likelihood_field_prob" else ""))
    s["beams"] = p.num("max_beams", lo=1, integer=True)
    rows.append((p.label("max_beams"), s["beams"], f"beams = {s['beams']}", "evenly spread, first and last kept"))
    lo_r, hi_r = p.num("laser_min_range"), p.num("laser_max_range")
    if lo_r > 0 and hi_r > 0 and lo_r >= hi_r:
        raise p.error("laser_min_range", f"{p.label('laser_min_range')} ({lo_r:g}) must be below "
                                         f"{p.label('laser_max_range')} ({hi_r:g}): no reading would be valid")
    s["min_range"] = lo_r if lo_r > 0 else None
    rows.append((p.label("laser_min_range"), lo_r, f"min_range = {_fmt(s['min_range'])}",
                 "the scan's range_min" if lo_r <= 0 else "shorter readings count as no return"))
    s["max_range"] = hi_r if hi_r > 0 else None
    rows.append((p.label("laser_max_range"), hi_r, f"max_range = {_fmt(s['max_range'])}",
                 "the scan's range_max" if hi_r <= 0 else ""))
    return sensor


def _likelihood_params(p: _Params, m: AmclMapping) -> dict[str, Any]:
    sp: dict[str, Any] = {}
    zh, zr = p.num("z_hit", lo=0.0), p.num("z_rand", lo=0.0)
    if zh + zr <= 0:
        raise p.error("z_hit", "z_hit + z_rand must be positive")
    sp["z_hit"], sp["z_rand"] = round(zh / (zh + zr), 12), round(zr / (zh + zr), 12)
    m.rows.append((f"{p.label('z_hit')}, {p.label('z_rand')}", (zh, zr),
                   f"z_hit = {sp['z_hit']:g}, z_rand = {sp['z_rand']:g}", "normalised to sum 1"))
    for c in ("z_short", "z_max", "lambda_short"):
        p.ignore_if_given(m, c, "not used by the likelihood field model (nor by AMCL's)")
    md = p.num("laser_likelihood_max_dist", lo=1e-9)
    sp["max_dist"] = md
    m.rows.append((p.label("laser_likelihood_max_dist"), md, f"max_dist = {md:g}", "distance-field cap"))
    return sp


def _beam_params(p: _Params, m: AmclMapping) -> dict[str, Any]:
    sp: dict[str, Any] = {}
    weights = ("z_hit", "z_short", "z_max", "z_rand")
    zs = [p.num(c, lo=0.0) for c in weights]
    tot = sum(zs)
    if tot <= 0:
        raise p.error("z_hit", "z_hit + z_short + z_max + z_rand must be positive")
    for c, v in zip(weights, zs):
        sp[c] = round(v / tot, 12)
    m.rows.append((", ".join(p.label(c) for c in weights), tuple(zs), ", ".join(f"{c} = {sp[c]:g}" for c in weights),
                   "normalised to sum 1"))
    sp["lambda_short"] = p.num("lambda_short", lo=1e-9)
    m.rows.append((p.label("lambda_short"), sp["lambda_short"], f"lambda_short = {sp['lambda_short']:g}", ""))
    if "laser_likelihood_max_dist" in p.vals:
        p.ignore_if_given(m, "laser_likelihood_max_dist", "used by the likelihood field only (as in AMCL)")
    p.used.add("laser_likelihood_max_dist")
    return sp


def _particles(p: _Params, m: AmclMapping) -> None:
    """Particle count and KLD-sampling."""
    s, rows = m.settings, m.rows
    n_min, n_max = p.num("min_particles", lo=1, integer=True), p.num("max_particles", lo=1, integer=True)
    if n_max < n_min:
        raise p.error("max_particles", f"max_particles ({n_max}) must be >= min_particles ({n_min})")
    err, z = p.num("pf_err", lo=1e-9, hi=1.0 - 1e-9), p.num("pf_z")
    s["particles"] = n_max
    pair, kld_pair = f"{p.label('min_particles')}, {p.label('max_particles')}", f"{p.label('pf_err')}, {p.label('pf_z')}"
    if n_min == n_max:
        s["kld"] = None
        rows.append((pair, (n_min, n_max), f"particles = {n_max}, no KLD-sampling", "min = max"))
        if "pf_err" in p.vals or "pf_z" in p.vals:
            rows.append((kld_pair, (err, z), "unused", "min_particles = max_particles"))
        return
    delta = 0.5 * math.erfc(z / math.sqrt(2.0))
    if not 0 < delta < 1:
        raise p.error("pf_z", f"{p.label('pf_z')} = {z:g} gives no usable confidence")
    s["kld"] = KLDSampling(epsilon=err, delta=delta, n_min=n_min, n_max=n_max)
    rows.append((pair, (n_min, n_max), f"particles = {n_max} at the start, KLD-sampling between {n_min} and {n_max}",
                 "AMCL starts with max_particles"))
    rows.append((kld_pair, (err, z), f"KLD epsilon = {err:g}, delta = {delta:.4g}",
                 "pf_z is the normal quantile z_(1-delta); bins 0.5 m x 0.5 m x 10 deg as AMCL's kd-tree"))


def _recovery(p: _Params, m: AmclMapping) -> None:
    """Augmented MCL from recovery_alpha_slow / _fast."""
    slow, fast = p.num("recovery_alpha_slow", lo=0.0, hi=1.0), p.num("recovery_alpha_fast", lo=0.0, hi=1.0)
    pair = f"{p.label('recovery_alpha_slow')}, {p.label('recovery_alpha_fast')}"
    if slow == 0 and fast == 0:
        m.settings["augmented"] = None
        m.rows.append((pair, (slow, fast), "augmented MCL off", ""))
        return
    try:
        m.settings["augmented"] = Augmented(alpha_slow=slow, alpha_fast=fast)
    except ValueError as exc:
        raise p.error("recovery_alpha_slow", f"recovery_alpha_slow/fast: {exc} (AMCL needs 0 < slow < fast < 1, "
                                             "e.g. 0.001, 0.1)") from None
    m.rows.append((pair, (slow, fast), f"augmented MCL (alpha_slow = {slow:g}, alpha_fast = {fast:g})", "PR table 8.3"))


def _resampling(p: _Params, m: AmclMapping) -> None:
    """resample_interval and ROS 1's selective_resampling as a resampling threshold."""
    s = m.settings
    ri = p.num("resample_interval", lo=1, integer=True)
    sel = p.orig.get("selective_resampling")
    if sel is not None:
        p.used.add("selective_resampling")
    if sel is True:
        s["resample_threshold"] = 0.5
        m.rows.append(("selective_resampling", True, "resample_threshold = 0.5", "resample when N_eff < N/2"))
        if ri != 1:
            m.ignored.append((p.label("resample_interval"), ri, "with selective resampling localize resamples "
                                                                 "whenever N_eff < N/2"))
    elif ri == 1:
        s["resample_threshold"] = 1.0
        m.rows.append((p.label("resample_interval"), ri, "resample_threshold = 1", "resample after every update"))
    else:
        s["resample_threshold"] = 0.5
        m.ignored.append((p.label("resample_interval"), ri, "resampling every k-th update has no counterpart; "
                                                             "localize resamples when N_eff < N/2"))


#: AMCL's default initial covariances (initial_cov_xx, _yy, _aa: 0.5 m, 0.5 m, pi/12 standard deviations).
_INITIAL_COV = {"initial_cov_xx": 0.25, "initial_cov_yy": 0.25, "initial_cov_aa": (math.pi / 12) ** 2}


def _finite(p: _Params, c: str, value: Any, label: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(float(value)):
        raise FormatError(p.source, p.where(c), f"{label} must be a number; got {value!r}")
    return float(value)


def _initial_pose(p: _Params, m: AmclMapping) -> None:
    """A known start: ROS 1's initial_pose_x/_y/_a, nav2's initial_pose (with set_initial_pose), initial_cov_*."""
    xya = ("initial_pose_x", "initial_pose_y", "initial_pose_a")
    if any(c in p.vals for c in xya):
        pose = tuple(_finite(p, c, p.vals.get(c, 0.0), c) for c in xya)
        label = ", ".join(xya)
    elif p.vals.get("set_initial_pose") is True and "initial_pose" in p.vals:
        d = p.vals["initial_pose"]
        if not isinstance(d, dict):
            raise FormatError(p.source, p.where("initial_pose"), f"initial_pose must hold x, y, yaw; got {d!r}")
        pose = tuple(_finite(p, "initial_pose", d.get(k, 0.0), f"initial_pose.{k}") for k in ("x", "y", "yaw"))
        label = "set_initial_pose, initial_pose"
        p.used.add("set_initial_pose")
    else:
        return
    p.used.update(xya + ("initial_pose",))
    var = []
    for c, default in _INITIAL_COV.items():
        p.used.add(c)
        v = _finite(p, c, p.vals.get(c, default), c)
        if v <= 0:
            raise FormatError(p.source, p.where(c), f"{c} must be a variance > 0; got {v:g}")
        var.append(v)
    std = tuple(round(math.sqrt(v), 6) for v in var)
    m.settings["initial_pose"], m.settings["initial_std"] = pose, std
    m.rows.append((label, pose, "initial_pose = ({:g}, {:g}, {:g})".format(*pose), "tracking from a known start"))
    m.rows.append(("initial_cov_xx, _yy, _aa", tuple(var), "initial_std = ({:g}, {:g}, {:g})".format(*std),
                   "standard deviations"))


def amcl_settings(params: dict, source: str = "<dict>", nav2: bool | None = None,
                  lines: list[str] | None = None) -> AmclMapping:
    """Map a dict of AMCL parameters (either dialect) to localize settings; see :func:`read_amcl_params`.

    Examples
    --------
    >>> m = amcl_settings({"kld_err": 0.05, "kld_z": 0.99, "min_particles": 500, "max_particles": 2000})
    >>> m.dialect, m.settings["particles"], round(m.settings["kld"].delta, 3), m.settings["kld"].n_min
    ('ros1', 2000, 0.161, 500)
    """
    if not isinstance(params, dict) or not params:
        raise FormatError(source, None, "no AMCL parameters found: expected keys such as alpha1 / odom_alpha1, "
                                        "max_particles, laser_model_type (nav2: under amcl: ros__parameters:)")
    p = _Params(params, source, nav2, lines)
    m = AmclMapping(dialect="nav2" if p.nav2 else "ros1", source=source)
    d_ref, a_ref = _motion(p, m)
    sensor = _laser(p, m)
    sp = _likelihood_params(p, m) if sensor == "likelihood" else _beam_params(p, m)
    m.settings["sigma_hit"] = p.num("sigma_hit", lo=1e-9)
    m.rows.append((p.label("sigma_hit"), m.settings["sigma_hit"], f"sigma_hit = {m.settings['sigma_hit']:g}", ""))
    m.settings["sensor_params"] = sp
    _particles(p, m)
    _recovery(p, m)
    m.settings["min_motion"] = (d_ref, a_ref)
    m.rows.append((f"{p.label('update_min_d')}, {p.label('update_min_a')}", (d_ref, a_ref),
                   f"min_motion = ({d_ref:g}, {a_ref:g})", ""))
    _resampling(p, m)
    _initial_pose(p, m)
    reasons = {n: r for r, ns in _IGNORED.items() for n in ns}
    for c, k in p.names.items():
        if c not in p.used:
            m.ignored.append((k, p.vals[c], reasons.get(c, "unknown AMCL parameter")))
    return m
