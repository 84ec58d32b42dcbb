"""Run by every kernel that the book's Jupyter server starts (``PYTHONSTARTUP``, set by jupyter_server_config.py).

Folds the output of solution cells after Run All (:mod:`localize.widgets._solutions`), then runs
the reader's own ``PYTHONSTARTUP`` file, if there was one. Outside a Jupyter kernel (a Python
prompt in JupyterLab's terminal) it does nothing but the latter.
"""


def _book_kernel_startup() -> None:
    import os
    import runpy
    import warnings

    try:
        from localize.widgets._solutions import install

        install()
    except Exception as err:  # noqa: BLE001 - a missing package must not stop the kernel
        warnings.warn(f"solution outputs will not be folded: {err}", stacklevel=1)
    own = os.environ.get("LOCALIZE_USER_PYTHONSTARTUP")
    if own and os.path.isfile(own):
        globals().update(runpy.run_path(own))


_book_kernel_startup()
del _book_kernel_startup
