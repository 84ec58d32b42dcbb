"""Screenshot a web page or HTML file in headless Chromium, the way an offline reader sees it.

    python tools/browser_screenshot.py _build/html/book/00_preface.html preface.png
    python tools/browser_screenshot.py http://127.0.0.1:8888/lab page.png --online --full-page

Uses Debian's Chromium (``/usr/bin/chromium``, or ``$LOCALIZE_CHROMIUM``) through the
``playwright`` Python package; Playwright's own browser download is not needed.
By default every request that leaves the machine (anything but ``file:``,
``data:``, ``blob:`` and 127.0.0.1/localhost) is blocked, so the picture shows
what a reader without internet gets, and the URLs that were blocked are
printed (e.g. MathJax or widget JavaScript loaded from a CDN): a page that
needs them does not render offline. ``--online`` lets them through.

Prints one line per blocked request and a final ``saved OUT (W x H px)``.
Exit status 0 on success, 2 when Chromium or playwright is missing.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path
from urllib.parse import urlparse

CHROMIUM = Path(os.environ.get("LOCALIZE_CHROMIUM", "/usr/bin/chromium"))
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update", "--no-first-run", "--disable-quic", "--disable-sync"]
LOCAL_SCHEMES = {"file", "data", "blob", "about", "chrome"}
LOCAL_HOSTS = {"127.0.0.1", "localhost", "::1", "[::1]"}


def is_local(url: str) -> bool:
    """True for URLs that do not leave the machine.

    Examples
    --------
    >>> is_local("file:///tmp/x.html"), is_local("http://127.0.0.1:8888/lab")
    (True, True)
    >>> is_local("https://cdn.jsdelivr.net/npm/mathjax@3/es5/tex-mml-chtml.js")
    False
    """
    u = urlparse(url)
    return u.scheme in LOCAL_SCHEMES or (u.hostname or "") in LOCAL_HOSTS


def to_url(target: str) -> str:
    """A URL for ``target``: URLs pass through, paths become ``file://`` URIs.

    Examples
    --------
    >>> to_url("http://127.0.0.1:1/x")
    'http://127.0.0.1:1/x'
    >>> to_url("/tmp/page.html")
    'file:///tmp/page.html'
    """
    if urlparse(target).scheme in {"http", "https", "file"}:
        return target
    return Path(target).resolve().as_uri()


def screenshot(target: str, out: Path, width: int = 1280, height: int = 900, full_page: bool = False,
               offline: bool = True, wait_ms: int = 500) -> list[str]:
    """Save a PNG screenshot of ``target`` to ``out``; return the external URLs that were blocked.

    Raises FileNotFoundError when Chromium is missing and ImportError when playwright is.
    """
    if not CHROMIUM.exists():
        raise FileNotFoundError(f"Chromium not found at {CHROMIUM}: apt-get install -y chromium "
                                "(or set LOCALIZE_CHROMIUM)")
    from playwright.sync_api import sync_playwright

    blocked: list[str] = []

    def route(r):
        if offline and not is_local(r.request.url):
            blocked.append(r.request.url)
            r.abort()
        else:
            r.continue_()

    out.parent.mkdir(parents=True, exist_ok=True)
    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=str(CHROMIUM), headless=True, args=CHROMIUM_ARGS)
        try:
            page = browser.new_page(viewport={"width": width, "height": height})
            page.route("**/*", route)
            page.goto(to_url(target), wait_until="load", timeout=60_000)
            page.wait_for_timeout(wait_ms)
            page.screenshot(path=str(out), full_page=full_page)
        finally:
            browser.close()
    return blocked


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("target", help="URL or path of an HTML file")
    ap.add_argument("out", type=Path, help="PNG file to write")
    ap.add_argument("--width", type=int, default=1280)
    ap.add_argument("--height", type=int, default=900)
    ap.add_argument("--full-page", action="store_true", help="capture the whole scrollable page")
    ap.add_argument("--online", action="store_true", help="let requests to other hosts through")
    ap.add_argument("--wait-ms", type=int, default=500, help="wait after load (fonts, math), default 500")
    args = ap.parse_args(argv)
    try:
        blocked = screenshot(args.target, args.out, args.width, args.height, args.full_page,
                             not args.online, args.wait_ms)
    except (FileNotFoundError, ImportError) as exc:
        print(f"cannot take a screenshot: {exc}", file=sys.stderr)
        return 2
    for url in blocked:
        print(f"blocked (not available offline): {url}")
    from PIL import Image

    with Image.open(args.out) as im:
        print(f"saved {args.out} ({im.width} x {im.height} px)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
