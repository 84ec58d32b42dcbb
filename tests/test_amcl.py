"""AMCL parameter files (localize.amcl) and ``localize run --amcl-params``.

The reference is nav2's default parameter file (tests/fixtures/nav2_params.yaml, the
amcl section of nav2_bringup/params/nav2_params.yaml); each parameter is checked
against the setting it must become.
"""

from __future__ import annotations

import io as stdio
import json
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import norm

pytest.importorskip("yaml")

from localize import amcl, cli, io, maps, sim  # noqa: E402
from localize.io import FormatError  # noqa: E402
from localize.kld import KLDSampling  # noqa: E402
from localize.mcl import Augmented  # noqa: E402

NAV2 = Path(__file__).parent / "fixtures" / "nav2_params.yaml"


@pytest.fixture(scope="module")
def nav2():
    return amcl.read_amcl_params(NAV2)


def test_fixture_holds_the_documented_nav2_defaults():
    import yaml

    p = yaml.safe_load(NAV2.read_text())["amcl"]["ros__parameters"]
    for k, v in amcl.NAV2_DEFAULTS.items():
        assert p[k] == v, k


@pytest.mark.parametrize("setting, expected", [
    ("alphas", (0.2, 0.2, 0.2, 0.2)),          # alpha1..4, differential model: PR variances as they are
    ("sensor", "likelihood"),                  # laser_model_type: likelihood_field
    ("beams", 60),                             # max_beams
    ("min_range", None),                       # laser_min_range: -1 = the scan's range_min
    ("max_range", 100.0),                      # laser_max_range
    ("sigma_hit", 0.2),                        # sigma_hit
    ("particles", 2000),                       # max_particles: AMCL's initial set
    ("augmented", None),                       # recovery_alpha_slow = recovery_alpha_fast = 0
    ("min_motion", (0.25, 0.2)),               # update_min_d, update_min_a
    ("resample_threshold", 1.0),               # resample_interval: 1
])
def test_nav2_defaults_map_parameter_by_parameter(nav2, setting, expected):
    assert nav2.settings[setting] == expected


def test_nav2_sensor_weights_and_kld(nav2):
    sp = nav2.settings["sensor_params"]
    assert sp == {"z_hit": 0.5, "z_rand": 0.5, "max_dist": 2.0}       # z_hit, z_rand; laser_likelihood_max_dist
    k = nav2.settings["kld"]
    assert isinstance(k, KLDSampling)
    assert (k.n_min, k.n_max, k.epsilon) == (500, 2000, 0.05)          # min/max_particles, pf_err
    assert k.delta == pytest.approx(norm.sf(0.99), rel=1e-12)          # pf_z is the quantile, not 1 - delta
    assert k.delta == pytest.approx(0.1611, abs=1e-4)
    assert k.bin_size == pytest.approx((0.5, 0.5, math.radians(10)))   # AMCL's kd-tree cells


def test_nav2_every_parameter_is_mapped_or_ignored_with_a_reason(nav2):
    import yaml

    keys = set(yaml.safe_load(NAV2.read_text())["amcl"]["ros__parameters"])
    ignored = {name for name, _, _ in nav2.ignored}
    assert ignored == {"alpha5", "z_short", "z_max", "lambda_short", "base_frame_id", "beam_skip_distance",
                       "beam_skip_error_threshold", "beam_skip_threshold", "do_beamskip", "global_frame_id",
                       "odom_frame_id", "random_seed", "save_pose_rate", "tf_broadcast", "transform_tolerance",
                       "introspection_mode", "scan_topic"}
    mapped = {n.strip().split(" ")[0] for row in nav2.rows for n in row[0].split(",")}
    mapped |= {"robot_model_type"}  # named inside the alphas row
    assert keys == mapped | ignored
    assert nav2.dialect == "nav2"
    w = nav2.warnings()
    assert len(w) == len(ignored) and all(line.startswith(f"{NAV2}: ignoring AMCL parameter ") for line in w)
    assert any("beam_skip_distance = 0.5: beam skipping is not implemented" in line for line in w)
    assert "KLD epsilon = 0.05, delta = 0.1611" in nav2.table()


# ------------------------------------------------------------------ AMCL's conventions, one by one
def m(**params):
    return amcl.amcl_settings(params)


def test_ros1_diff_corrected_alphas_are_pr_variances():
    s = m(odom_model_type="diff-corrected", odom_alpha1=0.1, odom_alpha2=0.02, odom_alpha3=0.03, odom_alpha4=0.04)
    assert s.settings["alphas"] == (0.1, 0.02, 0.03, 0.04) and s.dialect == "ros1"


def test_ros1_diff_model_draws_without_square_root():
    """ROS 1 'diff': std = a1*rot**2 + a2*trans**2; converted at one step of update_min_d / update_min_a."""
    s = m(odom_model_type="diff", odom_alpha1=0.1, odom_alpha2=0.2, odom_alpha3=0.3, odom_alpha4=0.4,
          update_min_d=0.5, update_min_a=0.25)
    a1, a2, a3, a4 = s.settings["alphas"]
    # each term's variance at the reference step equals (alpha * x**2)**2
    assert a1 * 0.25**2 == pytest.approx((0.1 * 0.25**2) ** 2)
    assert a2 * 0.5**2 == pytest.approx((0.2 * 0.5**2) ** 2)
    assert a3 * 0.5**2 == pytest.approx((0.3 * 0.5**2) ** 2)
    assert a4 * 0.25**2 == pytest.approx((0.4 * 0.25**2) ** 2)
    assert "no sqrt" in s.table()


def test_ros1_omni_swaps_alpha1_and_alpha4_back():
    s = m(odom_model_type="omni-corrected", odom_alpha1=0.1, odom_alpha2=0.2, odom_alpha3=0.3, odom_alpha4=0.4,
          odom_alpha5=0.5)
    assert s.settings["alphas"] == (0.4, 0.2, 0.3, 0.1)
    assert [r for r in s.ignored if r[0] == "odom_alpha5"][0][2].startswith("omni strafe noise")


def test_nav2_omni_model_keeps_the_documented_order():
    s = m(robot_model_type="nav2_amcl::OmniMotionModel", alpha1=0.1, alpha2=0.2, alpha3=0.3, alpha4=0.4)
    assert s.settings["alphas"] == (0.1, 0.2, 0.3, 0.4)


def test_kld_quantile_and_fixed_particle_count():
    s = m(pf_err=0.02, pf_z=2.3263478740408408, min_particles=100, max_particles=4000)
    assert s.settings["kld"].delta == pytest.approx(0.01, rel=1e-9) and s.settings["kld"].epsilon == 0.02
    s = m(min_particles=800, max_particles=800)
    assert s.settings["kld"] is None and s.settings["particles"] == 800
    with pytest.raises(FormatError, match="max_particles .100. must be >= min_particles .500."):
        m(min_particles=500, max_particles=100)


def test_recovery_alphas_are_augmented_mcl():
    s = m(recovery_alpha_slow=0.001, recovery_alpha_fast=0.1)
    assert s.settings["augmented"] == Augmented(alpha_slow=0.001, alpha_fast=0.1)
    with pytest.raises(FormatError, match="recovery_alpha_slow/fast: alpha_fast must lie in"):
        m(recovery_alpha_slow=0.2, recovery_alpha_fast=0.1)


def test_resampling():
    assert m(resample_interval=1).settings["resample_threshold"] == 1.0
    s = m(resample_interval=3)
    assert s.settings["resample_threshold"] == 0.5
    assert any(r[0] == "resample_interval" and "no counterpart" in r[2] for r in s.ignored)
    s = m(odom_model_type="diff-corrected", selective_resampling=True, resample_interval=1)
    assert s.settings["resample_threshold"] == 0.5


def test_beam_model_weights_are_normalised():
    s = m(laser_model_type="beam", z_hit=0.8, z_short=0.1, z_max=0.05, z_rand=0.05, lambda_short=0.2,
          laser_likelihood_max_dist=3.0)
    assert s.settings["sensor"] == "beam"
    sp = s.settings["sensor_params"]
    assert sp["z_hit"] == pytest.approx(0.8) and sum(sp[k] for k in ("z_hit", "z_short", "z_max", "z_rand")) == \
        pytest.approx(1.0, abs=1e-12)
    assert sp["lambda_short"] == 0.2 and "max_dist" not in sp
    assert any(r[0] == "laser_likelihood_max_dist" for r in s.ignored)
    lf = m(laser_model_type="likelihood_field", laser_z_hit=0.9, laser_z_rand=0.3).settings["sensor_params"]
    assert lf["z_hit"] == pytest.approx(0.75) and lf["z_rand"] == pytest.approx(0.25)


def test_likelihood_field_prob_and_ranges():
    s = m(laser_model_type="likelihood_field_prob", laser_min_range=0.3, laser_max_range=-1.0)
    assert s.settings["sensor"] == "likelihood" and "beam skipping" in s.table()
    assert s.settings["min_range"] == 0.3 and s.settings["max_range"] is None


def test_ros1_defaults_fill_missing_parameters():
    s = m(odom_model_type="diff-corrected")
    st = s.settings
    assert (st["beams"], st["particles"], st["kld"].n_min, st["kld"].epsilon) == (30, 5000, 100, 0.01)
    assert st["min_motion"] == pytest.approx((0.2, math.pi / 6))
    assert st["sensor_params"]["z_hit"] == pytest.approx(0.95)
    assert any(r[0] == "resample_interval (default)" for r in s.ignored)  # ROS 1's default is 2


def test_bad_files_name_the_parameter_and_line(tmp_path):
    p = tmp_path / "a.yaml"
    p.write_text("amcl:\n  ros__parameters:\n    max_beams: many\n")
    with pytest.raises(FormatError, match=r"a.yaml:3: max_beams must be a number; got 'many'"):
        amcl.read_amcl_params(p)
    p.write_text("amcl:\n  ros__parameters:\n    alpha1: [0.2\n")
    with pytest.raises(FormatError, match=r"a.yaml:\d+: not valid YAML"):
        amcl.read_amcl_params(p)
    p.write_text("odom_alpha1: 0.2\nalpha1: 0.3\n")
    with pytest.raises(FormatError, match="alpha1 and odom_alpha1 set the same AMCL parameter"):
        amcl.read_amcl_params(p)
    p.write_text("controller_server:\n  ros__parameters:\n    speed: 1\n")
    with pytest.raises(FormatError, match="no AMCL parameters found"):
        amcl.read_amcl_params(p)
    p.write_text("amcl:\n  ros__parameters:\n    laser_model_type: sonar\n")
    with pytest.raises(FormatError, match="a.yaml:3: laser_model_type: unknown model 'sonar'"):
        amcl.read_amcl_params(p)
    with pytest.raises(FormatError, match="no such file"):
        amcl.read_amcl_params(tmp_path / "missing.yaml")
    s = m(max_particles=100, min_particles=100, wobble=1)
    assert ("wobble", 1, "unknown AMCL parameter") in s.ignored


# ------------------------------------------------------------------ the command line
@pytest.fixture(scope="module")
def sim_files(tmp_path_factory):
    d = tmp_path_factory.mktemp("amcl_cli")
    grid = maps.office(0.1)
    run = sim.range_run(grid, np.random.default_rng(4), n_steps=30, dt=0.5, speed=0.4,
                        sensor_offset=(0.25, 0.0, 0.0), max_range=12.0, n_clutter=3)
    return io.write_cmu_map(d / "office.dat", grid), sim.write_cmu_log(d / "office.log", run)


def run_cli(*argv):
    out, err = stdio.StringIO(), stdio.StringIO()
    status = cli.main([str(a) for a in argv], stdout=out, stderr=err)
    return status, out.getvalue(), err.getvalue()


def test_cli_runs_with_nav2_parameters_and_prints_the_mapping(sim_files, tmp_path):
    map_path, log_path = sim_files
    status, out, err = run_cli("run", "--map", map_path, "--log", log_path, "--amcl-params", NAV2,
                               "--part", 400, "--out", tmp_path / "o")  # an abbreviated option still wins
    assert status == 0, err
    assert "AMCL parameters from" in out and "-> alphas = (0.2, 0.2, 0.2, 0.2)" in out
    assert "command-line options kept: --particles" in out
    assert "localize: warning: " in err and "ignoring AMCL parameter do_beamskip = False" in err
    s = json.loads((tmp_path / "o" / "summary.json").read_text())["settings"]
    assert s["alphas"] == [0.2, 0.2, 0.2, 0.2] and s["beams"] == 60 and s["min_motion"] == [0.25, 0.2]
    assert s["max_range"] == 100.0 and s["sigma_hit"] == 0.2 and s["resample_threshold"] == 1.0
    assert s["z_short"] == 0.0    # AMCL's likelihood field has no short-reading term
    assert s["kld"] == {"epsilon": 0.05, "delta": pytest.approx(norm.sf(0.99)), "n_min": 500, "n_max": 2000}
    assert s["amcl_params"]["dialect"] == "nav2" and "scan_topic" in s["amcl_params"]["ignored"]
    summary = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert summary["particles"] == 400


def test_cli_keeps_an_explicit_z_short_beside_amcl_parameters(sim_files, tmp_path):
    map_path, log_path = sim_files
    status, out, err = run_cli("run", "--map", map_path, "--log", log_path, "--amcl-params", NAV2,
                               "--particles", 400, "--z-short", 0.3, "--out", tmp_path / "o")
    assert status == 0, err
    assert "command-line options kept: --particles, --z-short" in out
    assert json.loads((tmp_path / "o" / "summary.json").read_text())["settings"]["z_short"] == 0.3


def test_help_shows_the_mapping_table(capsys):
    status, _, _ = run_cli("run", "--help")
    out = capsys.readouterr().out
    assert status == 0
    for line in ("pf_err, pf_z / kld_err, kld_z", "recovery_alpha_slow, recovery_alpha_fast", "--amcl-params"):
        assert line in out


def test_cli_wires_kld_and_augmented_mcl(sim_files, tmp_path):
    map_path, log_path = sim_files
    params = tmp_path / "ros1.yaml"
    params.write_text("odom_model_type: diff-corrected\nodom_alpha1: 0.05\nodom_alpha2: 0.01\nodom_alpha3: 0.02\n"
                      "odom_alpha4: 0.05\nmin_particles: 200\nmax_particles: 1500\nkld_err: 0.05\n"
                      "recovery_alpha_slow: 0.001\nrecovery_alpha_fast: 0.1\nlaser_model_type: beam\n"
                      "selective_resampling: true\n")
    status, _, err = run_cli("run", "--map", map_path, "--log", log_path, "--amcl-params", params, "--quiet",
                             "--out", tmp_path / "o")
    assert status == 0, err
    summary = json.loads((tmp_path / "o" / "summary.json").read_text())
    s = summary["settings"]
    assert s["augmented"] == [0.001, 0.1] and s["kld"]["n_min"] == 200 and s["kld"]["n_max"] == 1500
    assert s["sensor"] == "beam" and s["resample_threshold"] == 0.5 and s["beams"] == 30  # ROS 1 default
    assert summary["particles"] == 1500 and s["amcl_params"]["dialect"] == "ros1"
