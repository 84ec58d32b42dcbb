"""Interactive histogram filters: a hallway with doors and the coloured tile world.

Callbacks (pure functions from parameters to a matplotlib Figure, unit-tested):

* :func:`hallway_figure` — the 1-D Bayes filter after ``n_steps`` sense/move
  cycles, for a given sensor accuracy and motion noise;
* :func:`tile_world_figure` — the tile world after the first ``n_steps``
  sense/move cycles of :data:`TILE_PATH`.

Builders that wire ipywidgets to them: :func:`hallway_app` (sliders) and
:func:`tile_world_app` (sliders plus *step* and *reset* buttons). No widget
keeps module-level state.
"""

from __future__ import annotations

import numpy as np

from .. import discrete
from .. import histogram as hist
from ..maps import hallway, tile_world
from ..plot.histogram import draw_bars, draw_tiles
from . import interactive_app, show_figure, with_hint

__all__ = ["hallway_run", "hallway_figure", "tile_world_run", "tile_world_figure", "hallway_app",
           "tile_world_app", "TILE_START", "TILE_PATH", "DEMOS", "DEMO_VARIANTS"]

#: Where the robot of the tile-world demo starts (row, col), and the moves it makes between readings.
#: The first three readings (blue, green, red), with the moves left and up between them, are the
#: chapter's worked example.
TILE_START = (1, 4)
TILE_PATH = ["left", "up", "right", "right", "down", "down", "left", "down", "left", "left"]


def motion_kernel_1d(motion_noise: float) -> np.ndarray:
    """``[noise/2, 1 - noise, noise/2]``: under- and overshoot equally likely.

    Examples
    --------
    >>> motion_kernel_1d(0.2)
    array([0.1, 0.8, 0.1])
    """
    return np.array([motion_noise / 2, 1.0 - motion_noise, motion_noise / 2])


def _check_unit(x: float, name: str, lo: float = 0.0, hi: float = 1.0) -> float:
    v = float(x)
    if not lo <= v <= hi:
        raise ValueError(f"{name} must lie in [{lo}, {hi}]; got {x!r}")
    return v


def hallway_run(p_hit: float = 0.75, motion_noise: float = 0.2, n_steps: int = 3, cyclic: bool = True,
                world=None, start: int = 0):
    """Run the hallway filter: the robot starts at ``start``, reads door/wall (correctly), moves one cell right.

    Returns ``(prior, posterior, truth)`` of the last cycle: the belief before
    and after its measurement, and the true cell. ``p_hit`` is the chance the
    sensor is right (``p_miss = 1 - p_hit``).

    Examples
    --------
    >>> prior, post, truth = hallway_run(0.9, 0.0, 3)
    >>> truth, int(post.argmax())
    (2, 2)
    """
    p_hit = _check_unit(p_hit, "p_hit")
    motion_noise = _check_unit(motion_noise, "motion_noise")
    n_steps = int(n_steps)
    if n_steps < 1:
        raise ValueError(f"n_steps must be >= 1; got {n_steps}")
    w = hallway() if world is None else np.asarray(world)
    k = motion_kernel_1d(motion_noise)
    mode = "wrap" if cyclic else "constant"
    belief, truth = discrete.uniform(len(w)), int(start)
    prior = belief
    for t in range(n_steps):
        if t > 0:
            belief = discrete.normalize(discrete.predict(belief, k, 1, mode=mode))
            truth = (truth + 1) % len(w) if cyclic else min(truth + 1, len(w) - 1)
        prior = belief
        belief = discrete.update(belief, np.where(w == w[truth], p_hit, 1.0 - p_hit))
    return prior, belief, truth


def hallway_figure(p_hit: float = 0.75, motion_noise: float = 0.2, n_steps: int = 3, cyclic: bool = True):
    """Callback: the hallway belief after ``n_steps`` cycles: posterior bars, prior as a grey line.

    Examples
    --------
    >>> fig = hallway_figure(0.75, 0.2, 2)
    >>> len(fig.axes), len(fig.axes[0].patches) >= 20
    (1, True)
    """
    import matplotlib.pyplot as plt

    w = hallway()
    prior, post, truth = hallway_run(p_hit, motion_noise, n_steps, cyclic, w)
    fig, ax = plt.subplots(figsize=(7, 2.8))
    fig.subplots_adjust(left=0.1, right=0.98, bottom=0.16, top=0.88)
    top = max(prior.max(), post.max()) * 1.15
    draw_bars(post, ax, world=w, truth=truth, ylim=top,
              title=f"step {n_steps}: after reading '{'door' if w[truth] else 'wall'}' (bars); "
                    "before it (grey line)")
    ax.step(np.arange(len(prior) + 1) - 0.5, np.append(prior, prior[-1]), where="post", color="0.35", lw=1.2)
    return fig


def tile_world_run(p_hit: float = 0.85, motion_noise: float = 0.0, n_steps: int = 1, fill: float = 0.001):
    """Run the tile world for ``n_steps`` cycles along :data:`TILE_PATH`: the belief after the ``n_steps``-th reading.

    Like the worked example and the hallway (:func:`hallway_run`), a cycle
    ends on a reading: the first cycle only senses the colour under the
    robot, each later one first makes the next move of :data:`TILE_PATH`,
    then senses. So after 3 cycles the robot has read blue, moved left, read
    green, moved up and read red, and the belief is the example's last table
    (``n_steps`` from 0, the uniform prior, to ``len(TILE_PATH) + 1``).

    ``motion_noise`` is the chance of not reaching the intended tile, split
    as in the chapter: 80 % of it diagonally ahead, 20 % staying put (0.5
    gives the chapter's 0.5 / 0.2 / 0.2 / 0.1 model). Returns ``(belief,
    truth, readings)``.

    Examples
    --------
    >>> b, truth, z = tile_world_run(n_steps=3)
    >>> truth, z
    ((0, 3), ['blue', 'green', 'red'])
    >>> tuple(int(i) for i in np.unravel_index(b.argmax(), b.shape)), round(float(b.max()), 3)
    ((0, 3), 0.501)
    """
    p_hit = _check_unit(p_hit, "p_hit")
    motion_noise = _check_unit(motion_noise, "motion_noise")
    n_steps = int(n_steps)
    if not 0 <= n_steps <= len(TILE_PATH) + 1:
        raise ValueError(f"n_steps must lie in [0, {len(TILE_PATH) + 1}] (readings along TILE_PATH); got {n_steps}")
    w = tile_world()
    belief = discrete.uniform(w.shape)
    pos = np.array(TILE_START)
    readings = []
    for t in range(n_steps):
        if t > 0:                                    # move, then sense: the cycle ends on a reading
            name = TILE_PATH[t - 1]
            k = None if motion_noise == 0 else hist.noisy_step_kernel(name, 1.0 - motion_noise, 0.4 * motion_noise,
                                                                      0.2 * motion_noise)
            belief = hist.move(belief, name, k, fill=fill)
            pos = pos + hist.STEPS[name]
        z = str(w[tuple(pos)])
        readings.append(z)
        belief = hist.sense(belief, w, z, p_hit, 1.0 - p_hit)
    return belief, (int(pos[0]), int(pos[1])), readings


def tile_world_figure(p_hit: float = 0.85, motion_noise: float = 0.0, n_steps: int = 1):
    """Callback: the tile world with the belief after ``n_steps`` cycles; the true tile circled.

    Examples
    --------
    >>> fig = tile_world_figure(0.85, 0.0, 3)
    >>> fig.axes[0].get_title()
    'after 3 cycles (blue → left → green → up → red); most likely tile (0, 3)'
    """
    import matplotlib.pyplot as plt

    belief, truth, z = tile_world_run(p_hit, motion_noise, n_steps)
    fig, ax = plt.subplots(figsize=(5.6, 3.6))
    fig.subplots_adjust(left=0.06, right=0.98, bottom=0.08, top=0.9)
    best = np.unravel_index(int(belief.argmax()), belief.shape)
    story = [s for k, reading in enumerate(z) for s in ([TILE_PATH[k - 1]] if k else []) + [reading]]
    said = " → ".join(story if len(story) <= 5 else ["…"] + story[-4:]) if story else "nothing read"
    draw_tiles(tile_world(), belief, ax, truth=truth,
               title=f"after {n_steps} cycles ({said}); "
                     f"most likely tile ({int(best[0])}, {int(best[1])})")
    ax.title.set_fontsize(9)
    return fig


def hallway_app():
    """Sliders for sensor accuracy, motion noise and the number of cycles, redrawing :func:`hallway_figure`.

    Examples
    --------
    >>> app = hallway_app()
    >>> [c.description for c in app.children[:4]]
    ['sensor right', 'motion noise', 'cycles', 'cyclic world']
    >>> import matplotlib.pyplot as plt; plt.close("all")
    """
    from ipywidgets import Checkbox, FloatSlider, IntSlider

    return interactive_app(
        hallway_figure,
        p_hit=FloatSlider(value=0.75, min=0.5, max=1.0, step=0.05, description="sensor right"),
        motion_noise=FloatSlider(value=0.2, min=0.0, max=0.9, step=0.05, description="motion noise"),
        n_steps=IntSlider(value=3, min=1, max=20, description="cycles"),
        cyclic=Checkbox(value=True, description="cyclic world"),
    )


class _TileStepper:
    """State of the tile-world app: how many cycles have run. Its methods are the button callbacks."""

    def __init__(self) -> None:
        self.n_steps = 0

    def step(self, _=None) -> int:
        self.n_steps = min(self.n_steps + 1, len(TILE_PATH) + 1)
        return self.n_steps

    def reset(self, _=None) -> int:
        self.n_steps = 0
        return self.n_steps


def tile_world_app():
    """Sliders for sensor accuracy and motion noise, and *step* / *reset* buttons, redrawing the tile world.

    Examples
    --------
    >>> import contextlib, io
    >>> with contextlib.redirect_stdout(io.StringIO()):   # outside Jupyter the widget prints control codes
    ...     app = tile_world_app()
    ...     app.children[1].children[0].click()          # "next cycle": the first one only senses
    >>> app.stepper.n_steps
    1
    >>> import matplotlib.pyplot as plt; plt.close("all")
    """
    from ipywidgets import Button, FloatSlider, HBox, Output, VBox

    state = _TileStepper()
    p_hit = FloatSlider(value=0.85, min=0.5, max=1.0, step=0.05, description="sensor right")
    noise = FloatSlider(value=0.0, min=0.0, max=0.8, step=0.1, description="motion noise")
    step_b = Button(description="next cycle", tooltip="move one tile along the path, then sense (the first cycle only "
                                                       "senses): the belief after each reading, as in the worked example")
    reset_b = Button(description="reset")
    out = Output()

    def redraw(*_):
        with out:
            out.clear_output(wait=True)
            show_figure(tile_world_figure(p_hit.value, noise.value, state.n_steps))

    step_b.on_click(lambda b: (state.step(), redraw()))
    reset_b.on_click(lambda b: (state.reset(), redraw()))
    p_hit.observe(redraw, names="value")
    noise.observe(redraw, names="value")
    redraw()
    app = VBox([HBox([p_hit, noise]), HBox([step_b, reset_b]), out])
    app.stepper = state  # for tests
    app.redraw = redraw
    return with_hint(app)


DEMOS = {
    "hallway": lambda: hallway_figure(),
    "tile_world": lambda: tile_world_figure(),
}
DEMO_VARIANTS = {
    "hallway": [lambda: hallway_figure(0.95, 0.2, 3), lambda: hallway_figure(0.75, 0.6, 3)],
    "tile_world": [lambda: tile_world_figure(0.85, 0.0, 3), lambda: tile_world_figure(0.6, 0.5, 1)],
}
