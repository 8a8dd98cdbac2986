"""MkDocs hooks of the user guide (mkdocs.yml): pages generated while the site builds.

- ``demos/NAME.md`` from ``demos/NAME.py``: a jupytext percent script (``# %%`` cells) becomes its
  Markdown cells and code blocks (jupytext); any other demo its module docstring as text, then
  the script as one code block;
- ``benchmarks/FOLDER.md`` from ``benchmarks/FOLDER/README.md`` with the pictures it shows; a
  link to a file of the repository that is not a page becomes that path in code type (the site
  holds pages, not the repository);
- the nav entry ``Benchmarks`` becomes a section: the overview page and one page per folder.
"""

from __future__ import annotations

import re
from pathlib import Path

from mkdocs.structure.files import File, Files

ROOT = Path(__file__).resolve().parents[1]
LINK = re.compile(r"(!?)\[([^\]]*)\]\(([^)\s]+)\)")


def benchmark_folders() -> list[Path]:
    """Every benchmarks/ folder that has a README, in name order."""
    return sorted(p.parent for p in (ROOT / "benchmarks").glob("*/README.md"))


def on_config(config, **kwargs):
    nav = config["nav"]
    for i, entry in enumerate(nav):
        if isinstance(entry, dict) and "Benchmarks" in entry:
            pages = [{"Overview": entry["Benchmarks"]}]
            pages += [{folder.name: f"benchmarks/{folder.name}.md"} for folder in benchmark_folders()]
            nav[i] = {"Benchmarks": pages}
    return config


def _rst_to_markdown(text: str) -> str:
    """A docstring's reStructuredText habits in Markdown: section underlines become headings,
    double backticks single ones, ``::`` a colon."""
    lines = text.splitlines()
    out: list[str] = []
    i = 0
    while i < len(lines):
        line = lines[i]
        if i + 1 < len(lines) and line.strip() and re.fullmatch(r"-{3,}|={3,}", lines[i + 1].strip()):
            out.append("## " + line.strip())
            i += 2
            continue
        out.append(line)
        i += 1
    text = "\n".join(out).replace("``", "`")
    return re.sub(r"::\n", ":\n", text)


def demo_page(path: Path) -> str:
    """The Markdown page of a demo script."""
    source = path.read_text()
    relative = path.relative_to(ROOT)
    if re.search(r"^# %%", source, re.M):
        import jupytext

        notebook = jupytext.reads(source, fmt="py:percent")
        body = jupytext.writes(notebook, fmt="md")
        body = re.sub(r"\A---\n.*?\n---\n", "", body, flags=re.S)  # the jupytext header
        return f"<!-- generated from {relative} -->\n\n{body}\n\nThe script: `{relative}`.\n"
    match = re.match(r'\s*"""(.*?)"""\n(.*)', source, re.S)
    if not match:
        return f"# {path.stem}\n\n```python\n{source}\n```\n"
    doc, code = match.groups()
    title, _, rest = doc.strip().partition("\n")
    return (f"<!-- generated from {relative} -->\n\n# {title.strip().rstrip('.')}\n\n"
            f"{_rst_to_markdown(rest.strip())}\n\n"
            f"## The script (`{relative}`)\n\n```python\n{code.strip()}\n```\n")


def benchmark_page(folder: Path, pictures: list[Path]) -> str:
    """``folder/README.md`` as a page of the site; the pictures it shows are appended to ``pictures``."""
    names = {f.name for f in benchmark_folders()}

    def link(match: re.Match) -> str:
        bang, text, target = match.groups()
        if re.match(r"[a-z]+://|#|mailto:", target):
            return match.group(0)
        path, _, anchor = target.partition("#")
        resolved = (folder / path).resolve()
        if bang:
            if resolved.is_file():
                pictures.append(resolved)
                return f"![{text}]({folder.name}/{resolved.name})"
            return f"`{text}` (picture missing: {path})"
        if resolved.name == "README.md" and resolved.parent.parent == ROOT / "benchmarks" \
                and resolved.parent.name in names:
            return f"[{text}]({resolved.parent.name}.md{'#' + anchor if anchor else ''})"
        try:
            shown = resolved.relative_to(ROOT)
        except ValueError:
            shown = Path(path)
        return f"{text} (`{shown}`)" if text and text != str(path) and f"`{text}`" != f"`{shown}`" else f"`{shown}`"

    text = (folder / "README.md").read_text()
    parts = re.split(r"(```.*?```)", text, flags=re.S)  # leave code blocks alone
    body = "".join(part if part.startswith("```") else LINK.sub(link, part) for part in parts)
    return f"<!-- generated from benchmarks/{folder.name}/README.md -->\n\n{body}"


def on_files(files: Files, config, **kwargs) -> Files:
    for demo in sorted((ROOT / "demos").glob("*.py")):
        files.append(File.generated(config, f"demos/{demo.stem}.md", content=demo_page(demo)))
    for folder in benchmark_folders():
        pictures: list[Path] = []
        files.append(File.generated(config, f"benchmarks/{folder.name}.md", content=benchmark_page(folder, pictures)))
        for picture in dict.fromkeys(pictures):
            uri = f"benchmarks/{folder.name}/{picture.name}"
            if files.get_file_from_path(uri) is None:
                files.append(File.generated(config, uri, abs_src_path=str(picture)))
    return files
