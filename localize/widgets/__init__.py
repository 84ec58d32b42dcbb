"""Interactive figures (ipywidgets + matplotlib) for the book's chapters.

Every widget is built by a small function in a topic submodule
(``localize.widgets.motion`` ...). Each separates its *callback*, a plain
function from parameter values to a matplotlib figure (unit-tested without a
browser), from the widget wiring. No widget keeps module-level state, so two
widgets in one chapter never redraw each other's figure.
"""

from __future__ import annotations

__all__ = ["HINT", "with_hint"]

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
