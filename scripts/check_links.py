#!/usr/bin/env python3
"""Check the relative links of the book (docs/src/**/*.md) and README.md.

Every link that is not to another site must name a file or directory that exists, and a
`#anchor` must name a heading of the page it points to (ids made from the heading's text as
mdBook makes them: lower case, letters, digits, `_` and `-` kept, spaces to `-`, the rest
dropped; a repeated heading gets `-1`, `-2`, ...). A link from the book may not leave
docs/src: mdBook would not carry the file into the HTML. Standard library only.

Usage: check_links.py [ROOT]  (default: the repository above this script). Exits 1 and names
every broken link (file:line: target: why) when there is one.
"""
import re
import sys
from pathlib import Path

INLINE = re.compile(r"!?\[(?:[^\[\]]|\[[^\]]*\])*\]\(\s*<?([^)\s>]*)>?(?:\s+\"[^\"]*\")?\s*\)")
REFERENCE = re.compile(r"^\s{0,3}\[[^\]]+\]:\s*<?(\S+?)>?(?:\s+.*)?$")
HEADING = re.compile(r"^\s{0,3}(#{1,6})\s+(.*?)\s*#*\s*$")
FENCE = re.compile(r"^\s{0,3}(```|~~~)")
SCHEME = re.compile(r"^[a-zA-Z][a-zA-Z0-9+.-]*:")


def strip_code(line):
    """The line without its inline code spans (links inside them are not links)."""
    return re.sub(r"(`+)(?:(?!\1).)*?\1", "", line)


def lines_outside_fences(text):
    fence = None
    for number, line in enumerate(text.splitlines(), 1):
        m = FENCE.match(line)
        if m:
            if fence is None:
                fence = m.group(1)
            elif m.group(1) == fence:
                fence = None
            continue
        if fence is None:
            yield number, line


def heading_text(raw):
    """A heading's text as it reads: inline code's backticks, links' targets, emphasis gone."""
    text = re.sub(r"!?\[([^\]]*)\]\([^)]*\)", r"\1", raw)
    text = text.replace("`", "")
    text = re.sub(r"<[^>]+>", "", text)
    text = text.replace("*", "")
    return text


def normalize_id(text):
    out = []
    for ch in text:
        if ch.isalnum() or ch in "_-":
            out.append(ch.lower())
        elif ch.isspace():
            out.append("-")
    return "".join(out)


_anchors = {}


def anchors(path):
    if path not in _anchors:
        seen = {}
        ids = set()
        for _, line in lines_outside_fences(path.read_text(encoding="utf-8")):
            m = HEADING.match(line)
            if not m:
                continue
            base = normalize_id(heading_text(m.group(2)))
            n = seen.get(base, 0)
            ids.add(base if n == 0 else f"{base}-{n}")
            seen[base] = n + 1
        _anchors[path] = ids
    return _anchors[path]


def links(path):
    for number, line in lines_outside_fences(path.read_text(encoding="utf-8")):
        m = REFERENCE.match(line)
        if m:
            yield number, m.group(1)
            continue
        for m in INLINE.finditer(strip_code(line)):
            yield number, m.group(1)


def check(root):
    book = root / "docs" / "src"
    pages = sorted(book.rglob("*.md")) + [root / "README.md"]
    errors = []
    count = 0
    for page in pages:
        for number, target in links(page):
            if not target or SCHEME.match(target):
                continue
            count += 1
            where = f"{page.relative_to(root)}:{number}: {target}"
            path_part, _, anchor = target.partition("#")
            dest = page if not path_part else (page.parent / path_part).resolve()
            if path_part and not dest.exists():
                errors.append(f"{where}: no such file {dest.relative_to(root) if dest.is_relative_to(root) else dest}")
                continue
            if page.is_relative_to(book) and not dest.is_relative_to(book.resolve()):
                errors.append(f"{where}: leaves docs/src (mdBook does not carry it into the book)")
                continue
            if anchor:
                if dest.is_dir() or dest.suffix != ".md":
                    errors.append(f"{where}: an anchor into a file that is not a page")
                elif anchor not in anchors(dest):
                    errors.append(f"{where}: no heading '#{anchor}' in {dest.relative_to(root)}")
    return count, errors


def main():
    root = Path(sys.argv[1]).resolve() if len(sys.argv) > 1 else Path(__file__).resolve().parent.parent
    count, errors = check(root)
    for e in errors:
        print(f"broken link: {e}", file=sys.stderr)
    print(f"check_links: {count} relative links in docs/src and README.md, {len(errors)} broken")
    return 1 if errors else 0


if __name__ == "__main__":
    sys.exit(main())
