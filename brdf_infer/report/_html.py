"""One self-contained HTML file: figures embedded as base64 PNG, no external resources."""

from __future__ import annotations

import base64
import html
from collections.abc import Sequence

from brdf_infer.verdict import Verdict

STYLE = """
body { font-family: system-ui, sans-serif; max-width: 1150px; margin: 2em auto; padding: 0 1em;
  color: #222; }
h1 { font-size: 1.6em; } h2 { border-bottom: 1px solid #ccc; padding-bottom: .2em; }
table { border-collapse: collapse; margin: .6em 0; font-size: .9em; }
td, th { border: 1px solid #ddd; padding: .25em .6em; text-align: right; }
th { background: #f4f4f4; } td:first-child, th:first-child { text-align: left; }
.verdict { padding: .8em 1.2em; border-radius: 6px; margin: 1em 0; }
.result { padding: .4em 1.2em .8em; border: 1px solid #4a78c2; border-radius: 6px;
  background: #eef3fb; margin: 1em 0; }
.result h2 { border: none; margin: .3em 0; }
.result table { font-size: 1.05em; }
.result td:last-child, .result th:last-child { text-align: left; font-size: .85em; }
table { max-width: 100%; overflow-x: auto; display: block; }
.pass { background: #e6f4ea; border: 1px solid #34a853; }
.fail { background: #fce8e6; border: 1px solid #d93025; }
figure { margin: 1.2em 0; } figure img { max-width: 100%; }
figcaption { font-size: .9em; color: #555; }
pre { background: #f7f7f7; padding: .6em; overflow-x: auto; font-size: .85em; }
"""


def escape(text: object) -> str:
    return html.escape(str(text))


def table(headers: Sequence[str], rows: Sequence[Sequence[object]]) -> str:
    head = "".join(f"<th>{escape(h)}</th>" for h in headers)
    body = "".join("<tr>" + "".join(f"<td>{escape(c)}</td>" for c in row) + "</tr>" for row in rows)
    return f"<table><tr>{head}</tr>{body}</table>"


def figure(png: bytes, caption: str) -> str:
    data = base64.b64encode(png).decode("ascii")
    return (
        f'<figure><img alt="{escape(caption)}" src="data:image/png;base64,{data}">'
        f"<figcaption>{escape(caption)}</figcaption></figure>"
    )


def verdict_box(verdict: Verdict) -> str:
    """The run's verdict, its text exactly as the
    command line prints it after ``verdict:``; red when any check failed."""
    if verdict.ok:
        return (
            f'<div class="verdict pass"><strong>Verdict: {escape(verdict.text)}</strong> '
            "(every threshold below is met).</div>"
        )
    return (
        f'<div class="verdict fail"><strong>Verdict: {escape(verdict.text)}</strong>'
        f"<p>{len(verdict.lines)} check(s) failed: do not trust these results yet.</p></div>"
    )


def page(title: str, sections: Sequence[str]) -> str:
    return (
        '<!DOCTYPE html><html lang="en"><head><meta charset="utf-8">'
        f"<title>{escape(title)}</title><style>{STYLE}</style></head><body>"
        f"<h1>{escape(title)}</h1>" + "\n".join(sections) + "</body></html>"
    )
