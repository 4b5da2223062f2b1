"""How results show themselves in a notebook: one-line reprs elsewhere, and here the small HTML table of
``_repr_html_`` (key numbers only, never whole arrays)."""

from __future__ import annotations

import html
import math


def _cell(value) -> str:
    if isinstance(value, float):
        return f"{value:.6g}" if math.isfinite(value) else str(value)
    return str(value)


def summary_html(title: str, rows: dict) -> str:
    """A two-column HTML table headed by ``title``; values are formatted (floats to 6 digits) and escaped.

    Examples
    --------
    >>> summary_html("Run", {"E[H]": 0.5163245678, "method": "<jump>"})
    '<table><caption>Run</caption><tr><th style="text-align:left">E[H]</th><td>0.516325</td></tr><tr><th style="text-align:left">method</th><td>&lt;jump&gt;</td></tr></table>'
    """  # noqa: E501
    body = "".join(f'<tr><th style="text-align:left">{html.escape(str(k))}</th><td>{html.escape(_cell(v))}</td></tr>'
                   for k, v in rows.items())
    return f"<table><caption>{html.escape(title)}</caption>{body}</table>"
