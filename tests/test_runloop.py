"""The core run loop (localize.runloop.run), its record, and run_filter as the loop with the default policies."""

import inspect

import numpy as np
import pytest

from localize.kld import KLDSampling
from localize.maps import office
from localize.mcl import MCL, Augmented
from localize.policies import StateRules
from localize.raycast import RayCaster
from localize.runloop import Policies, Recorder, default_policies, run, run_filter
from localize.sensors import LikelihoodField

ANGLES = np.linspace(-np.pi / 2, np.pi / 2, 19)


def _drive(n=12):
    """Odometry poses and true scans of a robot driving east through the office (noise-free scans)."""
    g = office()
    truth = np.column_stack([np.linspace(2.0, 5.0, n), np.full(n, 3.0), np.zeros(n)])
    scans = RayCaster(g, 8.0, method="exact").cast(truth, ANGLES)
    return g, truth, scans


def _filter(g, seed, **options):
    lf = LikelihoodField(g, 8.0, sigma_hit=0.2, temper=0.3)
    return MCL.uniform(g, 800, (0.05, 0.05, 0.05, 0.05), lf, rng=np.random.default_rng(seed), **options)


@pytest.mark.parametrize("options", [
    {},
    {"injection": 0.1},
    {"augmented": Augmented(0.05, 0.5, temperature=10.0)},
    {"kld": KLDSampling(epsilon=0.1, n_min=200, n_max=800)},
    {"resample_threshold": 1.0, "free_space_only": True},
])
def test_the_bare_loop_is_a_loop_of_mcl_step_bit_for_bit(options):
    """No policies: run() must do exactly what MCL.step does at each step (same random draws, same bits)."""
    g, truth, scans = _drive()
    a, b = _filter(g, 7, **options), _filter(g, 7, **options)
    controls = [None] + [(truth[k - 1], truth[k]) for k in range(1, len(truth))]
    by_step = [a.step(controls[k], scans[k], ANGLES).pose for k in range(len(truth))]
    seen = []
    events = run(b, len(truth), lambda k: controls[k], lambda k: (scans[k], ANGLES),
                 observers=[lambda step, mcl: seen.append(step.pose)])
    assert events == []
    np.testing.assert_array_equal(np.array(seen), np.array(by_step))
    np.testing.assert_array_equal(b.particles, a.particles)
    np.testing.assert_array_equal(b.log_weights, a.log_weights)
    assert b.status == a.status


def test_the_core_loop_is_short_and_shows_the_textbook_steps():
    """The loop a student reads beside PR table 8.2: at most 50 lines, motion, update, estimate and resampling
    visible as calls on the filter."""
    src = inspect.getsource(run)
    assert len(src.splitlines()) <= 50
    body = src[src.index('"""', src.index('"""') + 3):]          # after the docstring
    for call in ("mcl.predict(u)", "mcl.update(*z", "p.estimate(step, mcl)", "mcl.needs_resampling()",
                 "mcl.resample("):
        assert call in body, call
    assert body.index("mcl.predict") < body.index("mcl.update") < body.index("p.estimate") < body.index(
        "mcl.resample")


def test_run_filter_is_the_core_loop_with_the_default_policies():
    g, truth, scans = _drive()
    kw = dict(restart_after=5, recovery_injection=0.05, expand=(0.1, 0.05), skip_short_beams=1.0,
              skip_unknown_beams=True, min_motion=(0.5, 0.5))
    controls = [None] + [(truth[k - 1], truth[k]) for k in range(1, len(truth))]
    tr = run_filter(_filter(g, 3), len(truth), lambda k: controls[k], lambda k: (scans[k], ANGLES), **kw)
    f = _filter(g, 3)
    rec = Recorder()
    events = run(f, len(truth), lambda k: controls[k], lambda k: (scans[k], ANGLES),
                 policies=default_policies(f, **kw), observers=[rec])
    again = rec.trace(events)
    np.testing.assert_array_equal(again.poses, tr.poses)
    np.testing.assert_array_equal(again.state, tr.state)
    assert again.events == tr.events
    assert tr.updated.sum() < len(truth)              # the motion gate left some scans out


def test_the_recorder_keeps_one_row_per_step_and_the_snapshots_asked_for():
    g, truth, scans = _drive(6)
    f = _filter(g, 1)
    rec = Recorder(snapshot_steps=[0, 4], snapshot_particles=50)
    events = run(f, 6, lambda k: (truth[k - 1], truth[k]), lambda k: (scans[k], ANGLES), observers=[rec])
    tr = rec.trace(events, seconds=1.5)
    assert len(tr) == 6 and tr.poses.shape == (6, 3) and tr.seconds == 1.5
    assert sorted(tr.snapshots) == [0, 4]
    parts, w = tr.snapshots[0]
    assert parts.shape == (50, 3) and w.shape == (50,)
    assert tr.beam_evaluations == 6 * 800 * len(ANGLES)
    assert tr.updated.all() and (tr.state == "searching").all()      # no state policy: no claim


def test_run_filter_checks_its_arguments():
    g, truth, scans = _drive(3)
    f = _filter(g, 0)
    for kw, msg in [({"recovery_injection": 1.0}, "recovery_injection"), ({"skip_short_beams": -1}, "skip_short"),
                    ({"expand": (np.nan, 0)}, "expand"), ({"grid": "map"}, "OccupancyGrid")]:
        with pytest.raises((ValueError, TypeError), match=msg):
            run_filter(f, 3, lambda k: None, lambda k: (scans[k], ANGLES), **kw)
    with pytest.raises(ValueError, match="n_steps"):
        run_filter(f, 0, lambda k: None, lambda k: None)


def test_a_policy_changes_the_filter_only_through_its_methods():
    """After a run with every policy switched on, the filter's settings are its own: no policy set
    ``injection`` or ``soft_obstacles`` on it and left it (the old driver did, and restored them)."""
    g, truth, scans = _drive()
    f = _filter(g, 5, injection=0.02, free_space_only=True, unknown_allowed=True, occupied_penalty=5.0)
    seen = []

    class Watch(MCL):
        pass

    f.__class__ = Watch

    def spy(self, name, value):
        seen.append(name)
        object.__setattr__(self, name, value)

    Watch.__setattr__ = spy
    run_filter(f, len(truth), lambda k: (truth[k - 1], truth[k]), lambda k: (scans[k], ANGLES), restart_after=2,
               recovery_injection=0.3, expand=(0.1, 0.1), skip_short_beams=1.0, rules=StateRules(hold=1))
    assert f.injection == 0.02 and f.soft_obstacles is True
    assert "injection" not in seen and "soft_obstacles" not in seen
    assert set(seen) <= {"particles", "log_weights"}


def test_policies_with_nothing_set_are_the_plain_filter():
    p = Policies()
    assert (p.odometry, p.gate, p.beams, p.evidence, p.restart, p.redraw, p.state) == (None,) * 7
    assert p.update_options() == {} and p.events == []


def test_the_trace_holds_a_symmetric_positive_semidefinite_covariance_per_step():
    g, truth, scans = _drive(8)
    tr = run_filter(_filter(g, 2), 8, lambda k: (truth[k - 1], truth[k]), lambda k: (scans[k], ANGLES),
                    snapshot_steps=[7])
    assert tr.cov.shape == (8, 3, 3)
    assert np.allclose(tr.cov, np.transpose(tr.cov, (0, 2, 1)))
    assert np.all(np.linalg.eigvalsh(tr.cov).min(axis=1) >= -1e-12)
    parts, w = tr.snapshots[7]
    from localize.estimate import estimate_pose

    np.testing.assert_allclose(tr.cov[7], estimate_pose(parts, w).cluster_cov, rtol=1e-9, atol=1e-12)
