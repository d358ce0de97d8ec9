#!/usr/bin/env python3
"""Do the documentation's relative links point somewhere? Offline, Python 3 standard library only.

    python3 scripts/check_docs_links.py

Reads README.md and every docs/*.md of the repository this script lives in. For each inline Markdown
link or image, `[text](path)`, `[text](path#anchor)` or `[text](#anchor)`, outside fenced code blocks and
inline code spans, it checks that the path names an existing file (or folder) in the repository and,
when there is an anchor, that the target Markdown file has a heading with that anchor. Links with a
scheme (http:, https:, mailto:, ...) are skipped.

Anchors follow GitHub's rule for headings: the heading's text (inline code and link text kept, markup
removed), lowercased, every character that is not a letter, digit, underscore, hyphen or space removed,
spaces turned into hyphens; a repeated anchor gets -1, -2, ... in order of appearance. Explicit HTML
anchors (`<a name="x">`, `id="x"`) count too.

Prints each broken link as FILE:LINE: message and exits 1 if there is any; else prints
"N links checked, 0 broken" and exits 0.
"""
import os
import re
import sys
import unicodedata
from urllib.parse import unquote

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

FENCE = re.compile(r"^ {0,3}(`{3,}|~{3,})")
ATX = re.compile(r"^ {0,3}(#{1,6})(?:[ \t]+(.*?))?(?:[ \t]+#+)?[ \t]*$")
SETEXT = re.compile(r"^ {0,3}(=+|-+)[ \t]*$")
CODE_SPAN = re.compile(r"(`+)(.+?)(?<!`)\1(?!`)")
# The destination of an inline link or image: `](dest)` or `](dest "title")`.
DESTINATION = re.compile(r"\]\(\s*(<[^>]*>|[^)\s]*)(?:\s+(?:\"[^\"]*\"|'[^']*'|\([^)]*\)))?\s*\)")
SCHEME = re.compile(r"^[A-Za-z][A-Za-z0-9+.-]*:")
HTML_ANCHOR = re.compile(r"<a\s[^>]*\bname=[\"']([^\"']+)[\"']|\bid=[\"']([^\"']+)[\"']", re.I)


def lines_outside_fences(text):
    """(line number, line) for every line outside fenced code blocks."""
    fence = None
    for number, line in enumerate(text.split("\n"), 1):
        m = FENCE.match(line)
        if fence is None:
            if m:
                fence = m.group(1)
            else:
                yield number, line
        elif m and m.group(1)[0] == fence[0] and len(m.group(1)) >= len(fence) \
                and not line[m.end():].strip():
            fence = None


def blank_code_spans(line):
    """The line with inline code spans replaced by spaces (columns kept)."""
    return CODE_SPAN.sub(lambda m: " " * len(m.group(0)), line)


def heading_text(raw):
    """A heading's text as rendered: code spans' content kept, links reduced to their text."""
    parts, last = [], 0
    for m in CODE_SPAN.finditer(raw):
        parts.append(markup_removed(raw[last:m.start()]))
        parts.append(m.group(2).strip())  # inline code is kept as written, HTML and all
        last = m.end()
    parts.append(markup_removed(raw[last:]))
    return "".join(parts).strip()


def markup_removed(text):
    text = re.sub(r"!?\[([^\]]*)\]\([^)]*\)", r"\1", text)
    return re.sub(r"<[^>]+>", "", text)


def slug(text):
    out = []
    for ch in text.lower():
        if ch in "-_ ":
            out.append(ch)
        elif unicodedata.category(ch)[0] in "LMN":
            out.append(ch)
    return "".join(out).replace(" ", "-")


def anchors_of(path, cache={}):
    if path in cache:
        return cache[path]
    with open(path, encoding="utf-8") as f:
        text = f.read()
    found, seen = set(), {}
    previous = None
    for _, line in lines_outside_fences(text):
        heading = None
        m = ATX.match(line)
        if m:
            heading = m.group(2) or ""
        elif previous is not None and previous.strip() and SETEXT.match(line) \
                and not previous.lstrip().startswith(("|", "-", "*", "+", ">")) \
                and not ATX.match(previous):
            heading = previous.strip()
        if heading is not None:
            base = slug(heading_text(heading))
            n = seen.get(base, 0)
            found.add(base if n == 0 else "%s-%d" % (base, n))
            seen[base] = n + 1
        for a, b in HTML_ANCHOR.findall(line):
            found.add(a or b)
        previous = line
    cache[path] = found
    return found


def documents():
    docs = [os.path.join(ROOT, "README.md")]
    folder = os.path.join(ROOT, "docs")
    if os.path.isdir(folder):
        docs += sorted(os.path.join(folder, n) for n in os.listdir(folder) if n.endswith(".md"))
    return [d for d in docs if os.path.isfile(d)]


def main():
    checked, broken = 0, []
    for doc in documents():
        shown = os.path.relpath(doc, ROOT)
        with open(doc, encoding="utf-8") as f:
            text = f.read()
        for number, line in lines_outside_fences(text):
            for m in DESTINATION.finditer(blank_code_spans(line)):
                dest = m.group(1)
                if dest.startswith("<") and dest.endswith(">"):
                    dest = dest[1:-1]
                if not dest or SCHEME.match(dest) or dest.startswith("//"):
                    continue
                checked += 1
                path, _, anchor = dest.partition("#")
                path, anchor = unquote(path), unquote(anchor)
                if path:
                    base = ROOT if path.startswith("/") else os.path.dirname(doc)
                    target = os.path.normpath(os.path.join(base, path.lstrip("/")))
                else:
                    target = doc
                if not (target == ROOT or target.startswith(ROOT + os.sep)):
                    broken.append("%s:%d: %s: points outside the repository" % (shown, number, dest))
                    continue
                if not os.path.exists(target):
                    broken.append("%s:%d: %s: no such file %s"
                                  % (shown, number, dest, os.path.relpath(target, ROOT)))
                    continue
                if anchor:
                    if not target.endswith(".md") or not os.path.isfile(target):
                        broken.append("%s:%d: %s: an anchor into a file that is not Markdown"
                                      % (shown, number, dest))
                    elif anchor not in anchors_of(target):
                        broken.append("%s:%d: %s: no heading with anchor #%s in %s"
                                      % (shown, number, dest, anchor, os.path.relpath(target, ROOT)))
    for b in broken:
        print(b)
    print("%d links checked, %d broken" % (checked, len(broken)))
    return 1 if broken else 0


if __name__ == "__main__":
    sys.exit(main())
