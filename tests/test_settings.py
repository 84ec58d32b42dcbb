"""localize.settings: one home for the settings of a run, the command line generated from it."""

from __future__ import annotations

import argparse
import copy
import dataclasses
import io as stdio
import json
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import norm

from localize import cli, io, maps, settings, sim
from localize.amcl import amcl_settings
from localize.pipeline import auto_particles
from localize.settings import DEFAULTS, RunSettings

NAV2 = Path(__file__).parent / "fixtures" / "nav2_params.yaml"
FIELDS = {f.name: f for f in dataclasses.fields(RunSettings)}
FLAGGED = [n for n, f in FIELDS.items() if f.metadata["flag"]]


def _run_parser() -> argparse.ArgumentParser:
    return cli.build_parser()._subparsers._group_actions[0].choices["run"]


def test_every_setting_has_a_default_a_range_and_a_help_line():
    for name, f in FIELDS.items():
        m = f.metadata
        assert m["help"] and "\n" not in m["help"], name
        assert callable(m["check"]), name
        if m["flag"] and m["choices"] is None and not isinstance(f.default, bool):
            assert m["valid"], f"{name}: no valid range"
    assert DEFAULTS == {n: getattr(RunSettings(), n) for n in FIELDS}
    assert settings.describe("temper") == ("temper (factor, (0, 1], default 0.3): factor on each scan's "
                                           "log-likelihood (neighbouring beams are not independent)")
    with pytest.raises(ValueError, match="no setting 'recovery'"):
        settings.describe("recovery")


def test_a_setting_has_one_name_from_flag_to_field():
    run = _run_parser()
    by_dest = {a.dest: a for a in run._actions}
    for name in FLAGGED:
        action = by_dest[name]
        assert action.option_strings[0] == "--" + name.replace("_", "-"), action.option_strings
        assert action.default == DEFAULTS[name] or isinstance(DEFAULTS[name], bool)
    # the command line's defaults are the settings' defaults
    args = cli.build_parser().parse_args(["run", "--log", "x", "--map", "m"])
    assert settings.from_namespace(args) == RunSettings()
    # the old flags are aliases of the new ones
    args = cli.build_parser().parse_args(["run", "--log", "x", "--map", "m", "--recovery", "0.1",
                                          "--short-beams", "0.5"])
    s = settings.from_namespace(args)
    assert (s.recovery_injection, s.skip_short_beams) == (0.1, 0.5)
    assert "--recovery-injection" in run.format_help() and "--skip-short-beams" in run.format_help()


def test_settings_are_frozen_and_checked_when_made():
    s = RunSettings()
    with pytest.raises(dataclasses.FrozenInstanceError):
        s.beams = 10
    t = dataclasses.replace(s, alphas=[0.1, 0.2, 0.3, 0.4], min_motion=[0, 0], particles=1e4)
    assert t.alphas == (0.1, 0.2, 0.3, 0.4) and t.min_motion == (0.0, 0.0) and t.particles == 10000
    assert s.alphas == (0.05, 0.01, 0.02, 0.05)                          # the original is unchanged
    for change, message in [(dict(temper=0), r"temper must be a number in \(0, 1\]; got 0"),
                            (dict(beams=2.5), "beams must be a whole number >= 1; got 2.5"),
                            (dict(sensor="sonar"), "sensor must be one of likelihood, beam; got 'sonar'"),
                            (dict(alphas=(0.1, 0.1)), "alphas must hold 4 numbers"),
                            (dict(particles="many"), "particles must be a whole number >= 1 or 'auto'"),
                            (dict(occupied_penalty=-1), "occupied_penalty must be a finite number of nats > 0 or 'inf'"),
                            (dict(recovery_injection=1.0), r"recovery_injection must be a fraction in \[0, 1\)"),
                            (dict(track="yes"), "track must be True or False"),
                            (dict(sensor_reset=0.1, state="thresholds"), "sensor_reset .* needs state .* probability")]:
        with pytest.raises((ValueError, TypeError), match=message):
            dataclasses.replace(s, **change)
    assert RunSettings(occupied_penalty="inf").occupied_penalty == np.inf


#: A value each numeric setting refuses.
BAD = {"particles": "0", "beams": "0", "max_range": "-1", "alphas": "-0.1", "sigma_hit": "0", "z_short": "1.5",
       "temper": "2", "min_motion": "-1", "injection": "1", "min_range": "-0.5", "kld": "-1", "min_particles": "0",
       "augmented": "-1", "recovery_injection": "1", "restart_after": "-2", "min_ess": "-1", "expand": "-1", "sensor_reset": "1",
       "skip_short_beams": "-1", "occupied_penalty": "0"}


@pytest.mark.parametrize("name", sorted(BAD))
def test_the_command_line_and_the_library_say_the_same(name, capsys):
    """The option's message is the library's, "NAME must be" read "expected" after argparse's "argument --flag:"."""
    f = FIELDS[name]
    flag = "--" + name.replace("_", "-")
    n = f.metadata["nargs"] or 1
    with pytest.raises(SystemExit):
        cli.build_parser().parse_args(["run", "--log", "x", "--map", "m", flag, *[BAD[name]] * n])
    err = capsys.readouterr().err.strip().splitlines()[-1]
    value = BAD[name] if n == 1 else [BAD[name]] * n
    with pytest.raises((ValueError, TypeError)) as lib:
        dataclasses.replace(RunSettings(), **{name: value})
    library = str(lib.value)
    if n == 1:       # a list is checked as a whole in the library, value by value on the command line
        assert err == f"localize run: error: argument {flag}: expected " + library[len(name + " must be "):]
    else:
        assert err.startswith(f"localize run: error: argument {flag}: expected a finite number >= 0")
        assert name in library


def test_the_parsed_arguments_are_never_changed(tmp_path):
    """Neither --particles auto nor an AMCL parameter file writes into the Namespace (both once did)."""
    grid = maps.office(0.1)
    run = sim.range_run(grid, np.random.default_rng(4), n_steps=8, dt=0.5, speed=0.4, max_range=12.0)
    map_path = io.write_cmu_map(tmp_path / "office.dat", grid)
    log_path = sim.write_cmu_log(tmp_path / "office.log", run)
    for extra in ([], ["--amcl-params", str(NAV2), "--beams", "20"]):
        argv = ["run", "--map", str(map_path), "--log", str(log_path), "--out", str(tmp_path / "o"), "--quiet",
                "--kld", "0.1", *extra]
        args = cli.build_parser().parse_args(argv)
        args._argv = argv
        before = copy.deepcopy(vars(args))
        assert cli._cmd_run(args, stdio.StringIO(), stdio.StringIO()) == 0
        assert vars(args) == before
        s = json.loads((tmp_path / "o" / "summary.json").read_text())["settings"]
        assert isinstance(s["particles"], int) and s["particles"] == (2000 if extra else auto_particles(grid))
        assert s["beams"] == (20 if extra else 30) and s["kld"]["epsilon"] == (0.05 if extra else 0.1)


def test_an_amcl_file_maps_onto_the_settings_and_the_command_line_wins():
    m = amcl_settings({"kld_err": 0.02, "kld_z": 0.99, "min_particles": 500, "max_particles": 5000,
                       "recovery_alpha_slow": 0.001, "recovery_alpha_fast": 0.1, "laser_model_type": "likelihood_field",
                       "z_hit": 0.5, "z_rand": 0.5, "laser_max_beams": 60, "resample_interval": 1})
    s, kept = settings.with_amcl(RunSettings(), m.settings)
    assert (s.particles, s.kld, s.min_particles, s.kld_max_particles, s.kld_chunked) == (5000, 0.02, 500, 5000, False)
    assert s.kld_delta == pytest.approx(norm.sf(0.99), rel=1e-9)           # delta = 1 - Phi(pf_z)
    assert (s.augmented, s.augmented_temperature, s.resample_threshold) == ((0.001, 0.1), 1.0, 1.0)
    assert s.sensor_params == {"z_hit": 0.5, "z_rand": 0.5, "max_dist": 2.0} and s.z_short == 0.0 and s.beams == 60
    assert kept == []
    s2, kept = settings.with_amcl(RunSettings(beams=40, z_short=0.3), m.settings, given={"beams", "z_short"})
    assert (s2.beams, s2.z_short, kept) == (40, 0.3, ["beams", "z_short"])
    # a beam model chosen on the command line does not take the file's likelihood-field weights
    s3, _ = settings.with_amcl(RunSettings(sensor="beam"), m.settings, given={"sensor"})
    assert s3.sensor == "beam" and s3.sensor_params == {}


def test_parse_options_is_what_the_command_line_runs():
    argv = ["--kld", "0", "--particles", "8000", "--alphas", "0.1", "0.2", "0.3", "0.4", "--track"]
    args = cli.build_parser().parse_args(["run", "--log", "x", "--map", "m", *argv])
    assert settings.parse_options(argv) == settings.from_namespace(args)
    assert settings.parse_options(argv).track and settings.parse_options(argv).alphas == (0.1, 0.2, 0.3, 0.4)
