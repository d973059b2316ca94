"""MkDocs hooks: the repository's own Markdown files outside ``docs/`` join the site, and
escaped pipes in table cells' code render as pipes.

The pages in ``docs/`` link to ``../reports/benchmarks.md``, ``../data/README.md`` and the
like, the paths that are right when the repository is browsed. MkDocs only knows the files
under ``docs_dir`` and, in strict mode, fails on such a link; this hook adds the files below
(and the images they show) to the site under those same relative paths, so a link to one is
checked like any other, and a link to a file that is not there still fails the build.
"""

from __future__ import annotations

import posixpath
import re
from pathlib import Path

from mkdocs.structure.files import File, Files, InclusionLevel

# repository folders whose Markdown pages and images the docs link to (not reports/<scene>/:
# run folders are not committed, except the example)
INCLUDED = ("data", "notebooks", "reports", "reports/example")
SUFFIXES = (".md", ".png")


def on_files(files: Files, config) -> Files:
    docs_dir = Path(config.docs_dir)
    repo = docs_dir.parent
    for folder in INCLUDED:
        for path in sorted((repo / folder).glob("*")):
            if path.suffix not in SUFFIXES or not path.is_file():
                continue
            rel = path.relative_to(repo).as_posix()
            # where the file would land were it under docs/ ...
            placed = File(rel, str(repo), config.site_dir, config.use_directory_urls)
            # ... under the name a docs page's relative link resolves to
            files.append(
                File(
                    posixpath.join("..", rel),
                    str(docs_dir),
                    config.site_dir,
                    config.use_directory_urls,
                    dest_uri=placed.dest_uri,
                    # (MkDocs' default exclusion of dot-paths would match the '..')
                    inclusion=InclusionLevel.NOT_IN_NAV,
                )
            )
    return files


def on_page_content(html: str, page, config, files) -> str:
    r"""A ``|`` in a table cell's code span is written ``\|`` (GitHub's tables need it);
    Python-Markdown leaves the backslash in the code, so it is taken out here."""
    return re.sub(r"<code>.*?</code>", lambda m: m.group(0).replace("\\|", "|"), html, flags=re.S)
