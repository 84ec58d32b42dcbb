"""The report picture (localize.plot.report): what a check can see in the rendered image."""

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from matplotlib.colors import to_rgb  # noqa: E402

from localize.maps import office  # noqa: E402
from localize.mcl import MCL, OdometryMotion  # noqa: E402
from localize.plot.report import STATE_COLORS, report_figure  # noqa: E402
from localize.runloop import run_filter  # noqa: E402
from localize.sensors import LikelihoodField  # noqa: E402
from localize.sim import range_run  # noqa: E402


@pytest.fixture(scope="module")
def tracked():
    g = office()
    angles = np.linspace(-np.pi, np.pi, 36, endpoint=False)
    r = range_run(g, np.random.default_rng(3), n_steps=30, angles=angles, max_range=8.0)
    lf = LikelihoodField(g, 8.0, sigma_hit=0.2, temper=0.1)
    f = MCL.gaussian(r.poses[0], (0.2, 0.2, 0.1), 2000, OdometryMotion(r.alphas, min_std=0.01), lf,
                     rng=np.random.default_rng(4), grid=g)
    tr = run_filter(f, 30, r.control, lambda k: (r.ranges[k], angles), snapshot_steps=[29])
    return g, r, tr


def _pixels_of(fig, ax, color, tol=0.06):
    """Data coordinates of the pixels of ``ax`` drawn in ``color``."""
    fig.canvas.draw()
    img = np.asarray(fig.canvas.buffer_rgba())[..., :3] / 255.0
    hits = np.argwhere(np.all(np.abs(img - np.array(to_rgb(color))) < tol, axis=-1))
    h = img.shape[0]
    disp = np.column_stack([hits[:, 1] + 0.5, h - hits[:, 0] - 0.5])     # row/col -> display (origin bottom left)
    legend = ax.get_legend().get_window_extent()
    disp = disp[~((disp[:, 0] >= legend.x0) & (disp[:, 0] <= legend.x1) & (disp[:, 1] >= legend.y0)
                  & (disp[:, 1] <= legend.y1))]                            # the legend's own marker
    xy = ax.transData.inverted().transform(disp)
    x0, x1 = ax.get_xlim()
    y0, y1 = ax.get_ylim()
    inside = (xy[:, 0] >= x0) & (xy[:, 0] <= x1) & (xy[:, 1] >= y0) & (xy[:, 1] <= y1)
    return xy[inside]


def test_the_trajectory_in_the_picture_lies_on_the_maps_free_space(tracked):
    g, r, tr = tracked
    assert (tr.state == "localized").sum() > 10
    fig = report_figure(g, tr, r.poses)
    ax = fig.axes[0]
    green = _pixels_of(fig, ax, STATE_COLORS["localized"])
    assert len(green) > 50                                  # the localized stretch is drawn ...
    cells = g.world_to_cell(green, outside="clip")
    on = ~g.occupied[cells[:, 0], cells[:, 1]]
    assert np.mean(on) > 0.95                               # ... over free space, where the robot drove
    # and where the estimates are: every green pixel is within a marker's radius of a localized pose
    loc = tr.poses[tr.state == "localized", :2]
    d = np.min(np.hypot(*(green[:, None, :] - loc[None, :, :]).transpose(2, 0, 1)), axis=1)
    assert np.quantile(d, 0.99) < 0.25
    plt.close(fig)


def test_the_picture_has_its_legend_and_both_panels(tracked):
    g, r, tr = tracked
    fig = report_figure(g, tr, r.poses, title="a run")
    labels = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    for want in ("final particles (2,000)", "reference", "estimate: localized", "start", "end"):
        assert any(lbl.startswith(want.split(" (")[0]) for lbl in labels), want
    assert fig.axes[1].get_ylabel().startswith("error against the reference")
    assert fig.axes[1].get_yscale() == "log"
    plt.close(fig)
    fig = report_figure(g, tr)                              # without a reference: the spread
    assert fig.axes[1].get_ylabel().startswith("spread")
    assert "reference" not in [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    plt.close(fig)


def test_the_probability_state_draws_both_columns_and_its_thresholds(tracked):
    """With the probability state, the time panel carries ``p_localized`` and ``p_place`` on a second axis (0-1),
    the very values of the trace, and the two thresholds the state is read from; the threshold state has none."""
    from localize.reliability import LOCALIZED_AT, LOST_BELOW

    g, r, _ = tracked
    angles = np.linspace(-np.pi, np.pi, 36, endpoint=False)
    lf = LikelihoodField(g, 8.0, sigma_hit=0.2, temper=0.1)
    f = MCL.gaussian(r.poses[0], (0.2, 0.2, 0.1), 2000, OdometryMotion(r.alphas, min_std=0.01), lf,
                     rng=np.random.default_rng(4), grid=g)
    tr = run_filter(f, 30, r.control, lambda k: (r.ranges[k], angles), state="probability")
    fig = report_figure(g, tr, r.poses)
    assert len(fig.axes) == 3
    twin = fig.axes[2]
    curves = {ln.get_label(): np.asarray(ln.get_ydata(), dtype=float) for ln in twin.lines if ln.get_label()[0] != "_"}
    assert set(curves) == {"p_localized (right axis)", "p_place (right axis)"}
    assert np.array_equal(curves["p_localized (right axis)"], tr.p_localized)
    assert np.array_equal(curves["p_place (right axis)"], tr.p_place)
    levels = sorted(float(ln.get_ydata()[0]) for ln in twin.lines if ln.get_label()[0] == "_")
    assert levels == [LOST_BELOW, LOCALIZED_AT] and twin.get_ylim() == (0.0, 1.02)
    legend = [t.get_text() for t in fig.axes[1].get_legend().get_texts()]
    assert "p_localized (right axis)" in legend and "localized" in legend
    plt.close(fig)
    fig = report_figure(g, tracked[2], r.poses)              # the threshold state: no probability, no second axis
    assert len(fig.axes) == 2
    plt.close(fig)


def test_a_reference_of_the_wrong_length_is_refused(tracked):
    g, r, tr = tracked
    with pytest.raises(ValueError, match="one pose per scan"):
        report_figure(g, tr, r.poses[:5])


def test_the_animation_titles_the_particles_the_filter_really_had_with_legend_trail_and_labels():
    """With KLD-sampling the cloud shrinks: each frame's title gives that frame's count (issue 44: the GIF said
    29,320 particles while the filter had 2,000), and a frame has its legend, trails and axis labels."""
    from localize.kld import KLDSampling
    from localize.plot.mcl import animate_snapshots

    g = office()
    angles = np.linspace(-np.pi, np.pi, 36, endpoint=False)
    r = range_run(g, np.random.default_rng(3), n_steps=12, angles=angles, max_range=8.0)
    lf = LikelihoodField(g, 8.0, sigma_hit=0.2, temper=0.1)
    f = MCL.uniform(g, 6000, OdometryMotion(r.alphas, min_std=0.01), lf, rng=np.random.default_rng(4),
                    kld=KLDSampling(epsilon=0.1, n_min=300, n_max=6000))
    tr = run_filter(f, 12, r.control, lambda k: (r.ranges[k], angles), snapshot_steps=[0, 11],
                    snapshot_particles=500)
    assert tr.n_particles[11] < 6000                       # KLD-sampling shrank the cloud
    counts = {k: int(tr.n_particles[k]) for k in tr.snapshots}
    anim = animate_snapshots(g, tr.snapshots, r.poses, tr.poses, n_particles=counts)
    ax = anim._fig.axes[0]
    anim._func(1)                                          # the frame of step 11
    assert ax.get_title().startswith(f"step 11: {counts[11]} particles") and "6000" not in ax.get_title()
    assert [t.get_text() for t in ax.get_legend().get_texts()] == ["true path", "estimated path", "particles"]
    trail = [ln for ln in ax.get_lines() if ln.get_label() == "estimated path"][0]
    assert len(trail.get_xdata()) == 12                    # the estimate's trail up to this frame
    assert ax.get_xlabel() == "x (m)" and ax.get_ylabel() == "y (m)"
    plt.close(anim._fig)
