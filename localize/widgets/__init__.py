"""Interactive figures (ipywidgets + matplotlib) for the book's chapters.

Every widget is built by a small function in a topic submodule
(``localize.widgets.motion`` ...). Each separates its *callback*, a plain
function from parameter values to a matplotlib figure (unit-tested without a
browser), from the widget wiring. No widget keeps module-level state, so two
widgets in one chapter never redraw each other's figure.
"""
