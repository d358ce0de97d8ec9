#!/usr/bin/env python3
"""Does a report page hold up in a real browser? Loads DIR/report/report.html's images in headless
Chromium and checks every link and image source of the page.

    python3 scripts/check_report.py results/<study> [--chromium PATH]

Checks: every `src` and `href` of the page names a file beside it (no network links); each image loads
in Chromium with a non-zero size (a wrapper page next to the report loads them as the page does and
writes what happened into its DOM, read back with --dump-dom); the page itself loads with no failed
resource in Chromium's log; the answer block (`id="answer"`) lies wholly inside a 1400 x 900 viewport
when the page opens, so a reader sees the answer without scrolling (--screenshot FILE keeps what the
browser showed, as PNG). Prints one line per image; exit 1 on any failure, 2 on bad usage.
"""
import argparse
import html.parser
import json
import os
import shutil
import subprocess
import sys


class Links(html.parser.HTMLParser):
    def __init__(self):
        super().__init__()
        self.images, self.links = [], []

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag == "img" and "src" in a:
            self.images.append(a["src"])
        if tag == "a" and "href" in a:
            self.links.append(a["href"])


def chromium_path(given):
    for name in [given, "chromium", "chromium-browser", "google-chrome"]:
        if name and shutil.which(name):
            return shutil.which(name)
    return None


def headless(chromium, page, budget_ms=10000):
    cmd = [chromium, "--headless", "--no-sandbox", "--disable-gpu", "--allow-file-access-from-files",
           "--enable-logging=stderr", "--v=0", f"--virtual-time-budget={budget_ms}", "--dump-dom",
           "file://" + os.path.abspath(page)]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=120)


VIEWPORT = (1400, 900)


def answer_in_view(chromium, page, screenshot=None):
    """Where the answer block lies when the page opens in a VIEWPORT window: a copy of the page beside
    it (so its images resolve) writes the block's box into its DOM; a failure text, or None."""
    text = open(page, encoding="utf-8").read()
    probe = os.path.join(os.path.dirname(page), ".check_answer.html")
    script = """<script>window.addEventListener("load", () => {
  const a = document.getElementById("answer"); const out = document.createElement("pre");
  out.id = "answer-box"; const r = a ? a.getBoundingClientRect() : null;
  out.textContent = r ? `BOX ${r.left} ${r.top} ${r.right} ${r.bottom} ${window.innerWidth} ${window.innerHeight}` : "BOX none";
  document.body.appendChild(out);
});</script></body>"""
    with open(probe, "w", encoding="utf-8") as f:
        f.write(text.replace("</body>", script, 1))
    size = f"--window-size={VIEWPORT[0]},{VIEWPORT[1]}"
    try:
        cmd = [chromium, "--headless", "--no-sandbox", "--disable-gpu", "--allow-file-access-from-files",
               "--hide-scrollbars", size, "--virtual-time-budget=10000", "--dump-dom", "file://" + os.path.abspath(probe)]
        dom = subprocess.run(cmd, capture_output=True, text=True, timeout=120).stdout
        if screenshot:
            cmd = [c for c in cmd if c != "--dump-dom"]
            cmd.insert(-1, "--screenshot=" + os.path.abspath(screenshot))
            subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    finally:
        os.remove(probe)
    box = dom.split('<pre id="answer-box">', 1)
    fields = box[1].split("<", 1)[0].replace("BOX", "", 1).split() if len(box) == 2 else []
    if not fields or fields[0] == "none":
        return "the page has no answer block (id=\"answer\")"
    left, top, right, bottom, width, height = (float(x) for x in fields)
    print(f"answer block at x {left:.0f}..{right:.0f}, y {top:.0f}..{bottom:.0f} in a {width:.0f} x {height:.0f} viewport")
    # The browser's own window frame takes some of the 900 px: the page's viewport is what it reports.
    if left < 0 or top < 0 or right > min(width, VIEWPORT[0]) or bottom > min(height, VIEWPORT[1]):
        return f"the answer block ({left:.0f}..{right:.0f} x {top:.0f}..{bottom:.0f} px) is not wholly inside the {width:.0f} x {height:.0f} viewport of a {VIEWPORT[0]} x {VIEWPORT[1]} window"
    return None


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dir", help="a results folder with report/report.html")
    ap.add_argument("--chromium", help="the browser binary (default: chromium on the PATH)")
    ap.add_argument("--screenshot", help="write what a 1400 x 900 window shows of the page here (PNG)")
    a = ap.parse_args()
    report = os.path.join(a.dir, "report")
    page = os.path.join(report, "report.html")
    if not os.path.isfile(page):
        print(f"error: {page}: no report page; run `fdimc report {a.dir}` first", file=sys.stderr)
        return 2
    chromium = chromium_path(a.chromium)
    if chromium is None:
        print("error: no chromium on the PATH (Debian: apt-get install chromium)", file=sys.stderr)
        return 2
    parser = Links()
    parser.feed(open(page, encoding="utf-8").read())
    failures = []
    for target in parser.images + parser.links:
        if "://" in target or target.startswith("//"):
            failures.append(f"{target}: a network link; the page must work offline")
        elif not target.startswith("#") and not os.path.isfile(os.path.join(report, target)):
            failures.append(f"{target}: no such file beside the page")
    if not parser.images:
        failures.append("the page has no image")

    # Load each image as the page does, in the browser, and write the outcome into the DOM.
    wrapper = os.path.join(report, ".check_images.html")
    sources = ",".join('"' + s.replace('"', '\\"') + '"' for s in parser.images)
    with open(wrapper, "w", encoding="utf-8") as f:
        f.write(f"""<!DOCTYPE html><html><body><pre id="out"></pre><script>
const srcs = [{sources}]; let left = srcs.length; const lines = [];
function done() {{ if (--left === 0) document.getElementById("out").textContent = "DONE\\n" + lines.join("\\n"); }}
for (const s of srcs) {{
  const im = new Image();
  im.onload = () => {{ lines.push((im.naturalWidth > 0 ? "ok " : "empty ") + im.naturalWidth + "x" + im.naturalHeight + " " + s); done(); }};
  im.onerror = () => {{ lines.push("failed " + s); done(); }};
  im.src = s;
}}
</script></body></html>""")
    try:
        dom = headless(chromium, wrapper).stdout
    finally:
        os.remove(wrapper)
    if "DONE" not in dom:
        failures.append("the browser did not finish loading the images")
    for line in dom.split("DONE", 1)[-1].split("</pre>")[0].strip().splitlines():
        print(line)
        if not line.startswith("ok "):
            failures.append(line)
    page_load = headless(chromium, page)
    for line in page_load.stderr.splitlines():
        if "Failed to load resource" in line or "ERR_FILE_NOT_FOUND" in line:
            failures.append("page: " + line.strip())
    if "<h1>fdimc report" not in page_load.stdout:
        failures.append("page: the browser did not render the report heading")
    # A sensitivity run's page shows its indices, not an answer block.
    manifest = os.path.join(a.dir, "manifest.json")
    sensitivity = os.path.isfile(manifest) and json.load(open(manifest, encoding="utf-8")).get("sensitivity")
    if not sensitivity:
        missing = answer_in_view(chromium, page, a.screenshot)
        if missing:
            failures.append("page: " + missing)
    for f in failures:
        print("FAIL " + f)
    print(f"{page}: {len(parser.images)} images, {len(parser.links)} links, {len(failures)} failure(s)")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
