"""Open built documentation pages in headless chromium and check that each renders without errors.

Usage: python scripts/docs_check.py HTML_DIR PAGE [PAGE ...]  (scripts/docs.sh runs it)

For each page: chromium loads it from disk and runs its scripts (``--dump-dom``); the check fails on a
console error (an uncaught exception, a resource that failed to load), a page without a title heading or
with little text, markup left unrendered (MyST fences or directives shown as text, TeX that MathJax did not typeset), a traceback in an
executed cell's output, or a local link or image whose file does not exist. A screenshot of each page
goes to HTML_DIR/../screenshots/ to look at.
"""

from __future__ import annotations

import html.parser
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path
from urllib.parse import unquote, urlparse

UNRENDERED = ("```", "{eval-rst}", "{code-cell}", ":::{", "{toctree}", "(hydrobuckle-", "\\(", "\\[", "$$")
CONSOLE_ERROR = re.compile(r"Uncaught|Failed to load resource|ERR_FILE_NOT_FOUND|SyntaxError|ReferenceError")


class _Page(html.parser.HTMLParser):
    def __init__(self):
        super().__init__()
        self.h1, self.links, self.text, self.prose = [], [], [], []
        self._in_h1 = self._skip = self._code = 0

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag == "h1":
            self._in_h1 += 1
            self.h1.append("")
        if tag in ("script", "style"):
            self._skip += 1
        if tag in ("pre", "code"):
            self._code += 1
        for attr in ("href", "src"):
            if tag in ("a", "img", "link", "script") and a.get(attr):
                self.links.append(a[attr])

    def handle_endtag(self, tag):
        if tag == "h1":
            self._in_h1 -= 1
        if tag in ("script", "style"):
            self._skip -= 1
        if tag in ("pre", "code"):
            self._code -= 1

    def handle_data(self, data):
        if self._skip:
            return
        if self._in_h1:
            self.h1[-1] += data
        self.text.append(data)
        if not self._code:
            self.prose.append(data)  # outside code blocks: where markup must have been rendered


def browser() -> str:
    for name in ("chromium", "chromium-browser", "google-chrome"):
        if shutil.which(name):
            return name
    raise SystemExit("docs_check: no chromium found (apt-get install chromium)")


def check(root: Path, page: str, shots: Path) -> list[str]:
    path = root / page
    if not path.is_file():
        return [f"{page}: not built"]
    url = path.resolve().as_uri()
    with tempfile.TemporaryDirectory() as profile:
        common = [browser(), "--headless", "--no-sandbox", "--disable-gpu", f"--user-data-dir={profile}",
                  "--enable-logging=stderr", "--v=0", "--virtual-time-budget=4000", "--hide-scrollbars"]
        dom = subprocess.run(common + ["--dump-dom", url], capture_output=True, text=True, timeout=120)
        shot = subprocess.run(common + [f"--screenshot={shots / (page.replace('/', '_') + '.png')}",
                                        "--window-size=1280,1400", url], capture_output=True, text=True, timeout=120)
    problems = []
    if dom.returncode != 0 or not dom.stdout.strip():
        problems.append(f"{page}: chromium exited {dom.returncode} with no page")
    for line in (dom.stderr + shot.stderr).splitlines():
        if "CONSOLE" in line and CONSOLE_ERROR.search(line) or "ERR_FILE_NOT_FOUND" in line:
            problems.append(f"{page}: console: {line.strip()[:300]}")
    parsed = _Page()
    parsed.feed(dom.stdout)
    text = " ".join(parsed.text)
    if not any(h.strip() for h in parsed.h1):
        problems.append(f"{page}: no title heading")
    if len(text.split()) < 100:
        problems.append(f"{page}: only {len(text.split())} words rendered")
    prose = " ".join(parsed.prose)
    for mark in UNRENDERED:
        if mark in prose:
            problems.append(f"{page}: unrendered markup {mark!r} in the text")
    if "Traceback (most recent call last)" in text:
        problems.append(f"{page}: a traceback in the page")
    for link in parsed.links:
        u = urlparse(link)
        if u.scheme or link.startswith("#") or link.startswith("//"):
            continue
        target = (path.parent / unquote(u.path)).resolve()
        if u.path and not target.exists():
            problems.append(f"{page}: broken local link {link}")
    return problems


def main(argv: list[str]) -> int:
    if len(argv) < 2:
        print(__doc__)
        return 2
    root = Path(argv[0])
    shots = root.parent / "screenshots"
    shots.mkdir(parents=True, exist_ok=True)
    problems = []
    for page in argv[1:]:
        found = check(root, page, shots)
        problems += found
        print(f"docs_check: {page}: {'ok' if not found else 'FAILED'}")
    for p in problems:
        print(f"docs_check: {p}", file=sys.stderr)
    return 1 if problems else 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
