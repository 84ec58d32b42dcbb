"""Callbacks of localize.widgets.histogram: they redraw, react to every parameter, and the buttons step."""

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from localize.widgets import histogram as wh  # noqa: E402


def test_hallway_run_sensor_accuracy_sharpens_belief():
    _, sharp, truth = wh.hallway_run(0.95, 0.1, 5)
    _, vague, _ = wh.hallway_run(0.6, 0.1, 5)
    assert sharp.argmax() == truth
    assert sharp.max() > vague.max()


def test_hallway_run_motion_noise_flattens_prior():
    prior_exact, _, _ = wh.hallway_run(0.9, 0.0, 4)
    prior_noisy, _, _ = wh.hallway_run(0.9, 0.6, 4)
    assert prior_noisy.max() < prior_exact.max()


def test_hallway_bounded_world():
    _, post, truth = wh.hallway_run(0.9, 0.2, 25, cyclic=False)
    assert truth == 19 and post.sum() == pytest.approx(1.0)


def test_tile_world_run_reproduces_worked_example():
    b, truth, z = wh.tile_world_run(0.85, 0.0, 1)
    # the first cycle only senses: 5 blue tiles of 35 get 0.85 / (5 * 0.85 + 30 * 0.15), the others 0.15 / ...
    assert z == ["blue"] and set(np.unique(b.round(3))) == {0.017, 0.097}
    # a cycle ends on a reading: after 3 cycles (blue, left, green, up, red) the robot is on the tile the
    # worked example circles, (0, 3), and the belief is the example's last table computed by localize
    from localize import histogram as hist
    from localize.maps import tile_world

    w = tile_world()
    ref = hist.sense(np.full(w.shape, 1.0 / w.size), w, "blue", 0.85, 0.15)
    ref = hist.sense(hist.move(ref, "left", fill=0.001), w, "green", 0.85, 0.15)
    ref = hist.sense(hist.move(ref, "up", fill=0.001), w, "red", 0.85, 0.15)
    b, truth, z = wh.tile_world_run(0.85, 0.0, 3)
    assert z == ["blue", "green", "red"] and truth == (0, 3)
    np.testing.assert_allclose(b, ref, rtol=1e-12)
    assert tuple(np.unravel_index(b.argmax(), b.shape)) == (0, 3)
    b, truth, z = wh.tile_world_run(0.85, 0.0, len(wh.TILE_PATH))
    assert tuple(np.unravel_index(b.argmax(), b.shape)) == truth


def test_figures_change_with_parameters():
    def title_texts(fig):
        out = [t.get_text() for ax in fig.axes for t in ax.texts]
        plt.close(fig)
        return out
    assert title_texts(wh.tile_world_figure(0.85, 0.0, 2)) != title_texts(wh.tile_world_figure(0.7, 0.0, 2))
    assert title_texts(wh.tile_world_figure(0.85, 0.0, 2)) != title_texts(wh.tile_world_figure(0.85, 0.5, 2))
    f1, f2 = wh.hallway_figure(0.75, 0.2, 3), wh.hallway_figure(0.9, 0.2, 3)
    h1 = [p.get_height() for p in f1.axes[0].patches]
    h2 = [p.get_height() for p in f2.axes[0].patches]
    plt.close(f1)
    plt.close(f2)
    assert not np.allclose(h1, h2)


def test_bad_parameters():
    with pytest.raises(ValueError, match="p_hit"):
        wh.hallway_run(1.5)
    with pytest.raises(ValueError, match="n_steps"):
        wh.tile_world_run(n_steps=99)
    with pytest.raises(ValueError, match="motion_noise"):
        wh.tile_world_run(motion_noise=-0.1)


def test_apps_build_and_buttons_step():
    app = wh.hallway_app()
    assert len(app.children) >= 4
    tile = wh.tile_world_app()
    assert tile.stepper.n_steps == 0
    step_button, reset_button = tile.children[1].children
    step_button.click()
    step_button.click()
    assert tile.stepper.n_steps == 2
    for _ in range(20):
        tile.stepper.step()     # the button's callback, without 20 redraws
    assert tile.stepper.n_steps == len(wh.TILE_PATH) + 1
    reset_button.click()
    assert tile.stepper.n_steps == 0
    tile.children[0].children[0].value = 0.7   # slider redraw does not raise
    plt.close("all")
