"""Interactive figures (ipywidgets + matplotlib) for the book's chapters.

Every widget is built by a small function in a topic submodule
(``localize.widgets.motion`` ...). Each separates its *callback*, a plain
function from parameter values to a matplotlib figure (unit-tested without a
browser), from the widget wiring. No widget keeps module-level state, so two
widgets in one chapter never redraw each other's figure.
"""

from __future__ import annotations

import contextlib
import functools
import io

__all__ = ["HINT", "with_hint", "interactive_app", "figure_output", "show_figure", "slider", "quiet_outside_ipython"]

#: What a reader sees in place of a widget before the notebook has been run
#: (an untrusted or not yet executed notebook can only show the plain-text form).
HINT = ("▶ Interactive figure: run this cell (or Run → Run All Cells) to get the sliders. "
        "The figure below shows the default setting.")

_HINTED: dict[type, type] = {}


def with_hint(widget, hint: str = HINT):
    """Give an ipywidgets container a helpful plain-text form instead of its repr.

    A notebook that has not been run in this session (or is untrusted) shows
    the text/plain form of a widget output: for a container, a long
    ``VBox(children=(HBox(...`` repr. This swaps it for ``hint`` (also offered
    as Markdown); a live kernel still shows the widget. Returns the widget.

    Examples
    --------
    >>> import ipywidgets as W
    >>> box = with_hint(W.VBox([W.IntSlider()]))
    >>> repr(box)[:22]
    '▶ Interactive figure: '
    >>> type(box).__mro__[1].__name__
    'VBox'
    >>> box._repr_mimebundle_()["text/markdown"][:22] == repr(box)[:22]
    True
    """
    base = type(widget)
    if base not in _HINTED:
        def __repr__(self):
            return self._localize_hint

        def _repr_mimebundle_(self, **kwargs):
            data = base._repr_mimebundle_(self, **kwargs) or {}
            data["text/plain"] = self._localize_hint
            data["text/markdown"] = self._localize_hint
            return data

        _HINTED[base] = type(base.__name__, (base,), {"__repr__": __repr__, "_repr_mimebundle_": _repr_mimebundle_,
                                                      "__module__": base.__module__})
    widget.__class__ = _HINTED[base]
    widget._localize_hint = str(hint)
    _full_labels(widget)
    return widget


def _full_labels(widget) -> None:
    """Let every control's label take the width it needs (the default cuts labels after ~10 characters)."""
    stack = [widget]
    while stack:
        wd = stack.pop()
        style = getattr(wd, "style", None)
        if getattr(wd, "description", "") and style is not None and hasattr(style, "description_width"):
            style.description_width = "initial"
        stack.extend(getattr(wd, "children", ()))


@contextlib.contextmanager
def quiet_outside_ipython():
    """Swallow what ipywidgets prints to a terminal while a widget is built and first drawn.

    Outside IPython (a script, a doctest, a test) each redraw's
    ``clear_output`` writes clear-line control codes to stdout; a notebook
    prints nothing there, so inside IPython this does nothing.
    """
    try:
        from IPython import get_ipython
    except ImportError:  # pragma: no cover - IPython comes with ipywidgets
        get_ipython = None
    if get_ipython is not None and get_ipython() is not None:
        yield
        return
    with contextlib.redirect_stdout(io.StringIO()):
        yield


def show_figure(fig) -> None:
    """Show a matplotlib Figure as a PNG where output goes now (inside an Output widget: in it), then close it.

    The one way every widget of the book shows its figure. It works for any
    figure, a pyplot one or a bare ``matplotlib.figure.Figure``, whatever the
    matplotlib backend: ``ipywidgets.interactive`` displays nothing that its
    callback returns, and the inline backend shows only pyplot figures (a
    widget whose callback returned a bare Figure showed its controls and no
    figure). The figure is rendered like the inline backend renders
    (``bbox_inches="tight"``, the figure's dpi) and released from pyplot, so
    that it is not shown a second time below the widget when the cell ends.
    Outside IPython (a script, a test) nothing is rendered.

    Examples
    --------
    >>> from matplotlib.figure import Figure
    >>> fig = Figure(); _ = fig.subplots().plot([0, 1])
    >>> show_figure(fig)          # outside IPython: nothing to show, no output
    """
    if fig is None:
        return
    import sys

    pyplot = sys.modules.get("matplotlib.pyplot")
    try:
        from IPython import get_ipython
        from IPython.display import display
    except ImportError:  # pragma: no cover - IPython comes with ipywidgets
        get_ipython = None
    if get_ipython is not None and get_ipython() is not None:
        buf = io.BytesIO()
        fig.savefig(buf, format="png", bbox_inches="tight", facecolor=fig.get_facecolor())
        display({"image/png": buf.getvalue(), "text/plain": repr(fig)}, raw=True)
    if pyplot is not None:
        pyplot.close(fig)


def _displaying(figure):
    """``figure`` (returning a Figure, or None after printing why not) wrapped to show its result.

    The wrapper keeps ``figure``'s signature (``ipywidgets.interactive`` reads
    the defaults from it) and remembers the last figure as ``.last``.
    """
    @functools.wraps(figure)
    def show(*args, **kwargs):
        fig = figure(*args, **kwargs)
        show.last = fig
        if fig is not None and hasattr(fig, "savefig"):
            show_figure(fig)
        elif fig is not None:
            from IPython.display import display

            display(fig)

    show.last = None
    return show


def interactive_app(figure, hint: str = HINT, **controls):
    """``figure`` redrawn by ``controls``: ``ipywidgets.interactive`` that shows the figure the callback returns.

    ``figure`` maps the controls' values (keyword arguments named like the
    controls; ``ipywidgets.fixed`` for constants) to a matplotlib Figure, the
    unit-tested callback of a widget module; each figure is shown in the
    widget's output area with :func:`show_figure`, whether it is a pyplot
    figure or not. Built quietly outside a notebook
    (:func:`quiet_outside_ipython`). ``app.callback.last`` is the figure of
    the last redraw.

    Examples
    --------
    >>> from matplotlib.figure import Figure
    >>> def figure(a=1.0):
    ...     fig = Figure(); fig.subplots().plot([0, a]); return fig
    >>> app = interactive_app(figure, a=slider(1.0, 0.0, 2.0, 0.5, "a"))
    >>> [c.description for c in app.children[:1]], app.children[0].continuous_update
    (['a'], False)
    >>> with quiet_outside_ipython():
    ...     app.children[0].value = 2.0
    >>> app.callback.last.axes[0].lines[0].get_ydata().tolist()
    [0.0, 2.0]
    """
    from ipywidgets import interactive

    show = _displaying(figure)
    with quiet_outside_ipython():
        app = with_hint(interactive(show, **controls), hint)
    app.callback = show
    return app


def figure_output(figure, controls: dict):
    """An Output widget showing ``figure(**values of controls)``, redrawn when a control changes.

    Like ``ipywidgets.interactive_output``, for builders that lay out their
    controls themselves; the figure is shown with :func:`show_figure`.
    ``out.callback.last`` is the figure of the last redraw.

    Examples
    --------
    >>> import ipywidgets as W
    >>> from matplotlib.figure import Figure
    >>> def figure(a):
    ...     fig = Figure(); fig.subplots().set_title(f"a = {a}"); return fig
    >>> a = W.IntSlider(value=1)
    >>> out = figure_output(figure, {"a": a})
    >>> with quiet_outside_ipython():
    ...     a.value = 3
    >>> out.callback.last.axes[0].get_title()
    'a = 3'
    """
    from ipywidgets import interactive_output

    show = _displaying(figure)
    with quiet_outside_ipython():
        out = interactive_output(show, controls)
    out.callback = show
    return out


def slider(value: float, lo: float, hi: float, step: float, description: str, fmt: str = ".2f", log: bool = False):
    """A float slider that redraws on release (``continuous_update=False``), its readout in ``fmt``.

    ``log=True`` gives a ``FloatLogSlider`` whose ``lo``, ``hi`` and ``step``
    are powers of ten.
    """
    import ipywidgets as W

    kind = W.FloatLogSlider if log else W.FloatSlider
    extra = {"base": 10} if log else {}
    return kind(value=value, min=lo, max=hi, step=step, description=description, readout_format=fmt,
                continuous_update=False, **extra)
