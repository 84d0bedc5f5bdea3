"""Text of a divergence report: ``btlog diff``'s side-by-side table, one row per action.

Every recorded string goes through ``safe`` (terminal escapes neutralised). Divergent rows
start with ``!`` and show the action's immediate parent, as in the paper's Fig. 14.
"""

from __future__ import annotations

from collections.abc import Iterator

from btlog.explain.divergence import Divergence, ExecutedAction, Move, SubgoalDivergence
from btlog.render.escape import safe


def move_text(move: Move) -> str:
    """E.g. ``"scan scene" moved later, past "attach gear"``."""
    text = f'"{safe(move.action)}" moved {move.direction}'
    if move.past:
        text += ", past " + ", ".join(f'"{safe(p)}"' for p in move.past)
    return text


def _cell(action: ExecutedAction | None, divergent: bool) -> str:
    if action is None:
        return ""
    text = safe(action.description)
    if divergent and action.parent:
        text += f"  (in {safe(action.parent)})"
    return text


def subgoal_header(found: SubgoalDivergence) -> str:
    """One line: the subgoal with its edit distance and LCS length."""
    line = (
        f'subgoal "{safe(found.subgoal)}": edit distance {found.edit_distance}, '
        f"LCS length {found.lcs_length} ({len(found.a_actions)} vs "
        f"{len(found.b_actions)} actions)"
    )
    if found.moves:
        line += "; " + "; ".join(move_text(move) for move in found.moves)
    if found.cut is not None:
        line += "; " + found.cut.text()
    return line


def render_lines(divergence: Divergence, only_divergent: bool = False) -> list[tuple[str, str]]:
    """The side-by-side report as a list of ``(text, kind)`` lines (see ``iter_lines``)."""
    return list(iter_lines(divergence, only_divergent))


def iter_lines(divergence: Divergence, only_divergent: bool = False) -> Iterator[tuple[str, str]]:
    """The side-by-side report as ``(text, kind)`` lines, one at a time (a day-long run's
    report is never held whole); kind is "title", "header", "row", "divergent", "blank"
    or "summary" (for styling). Divergent rows start with ``!``; the missing side is
    blank. ``only_divergent`` leaves out the rows of subgoals that agree."""
    cells = (len(_cell(r.a, r.divergent)) for s in divergence.subgoals for r in s.rows)
    width = max(max(cells, default=0), len(safe(divergence.a_label)) + 3, 20)
    yield (f"A: {safe(divergence.a_label)}", "title")
    yield (f"B: {safe(divergence.b_label)}", "title")
    for found in divergence.subgoals:
        yield ("", "blank")
        yield (subgoal_header(found), "header")
        if only_divergent and not found.diverges:
            continue
        yield (f"    {'A':<{width}}   B", "header")
        for row in found.rows:
            mark = "! " if row.divergent else "  "
            left, right = _cell(row.a, row.divergent), _cell(row.b, row.divergent)
            text = f"  {mark}{left:<{width}}   {right}".rstrip()
            yield (text, "divergent" if row.divergent else "row")
    yield ("", "blank")
    yield (_summary(divergence), "summary")


def _summary(divergence: Divergence) -> str:
    count = len(divergence.subgoals)
    if divergence.identical:
        return f"no divergence in {count} subgoal{'s' if count != 1 else ''}"
    diverging = len(divergence.divergent_subgoals)
    return (
        f"total edit distance {divergence.edit_distance}: {diverging} of {count} "
        f"subgoal{'s' if count != 1 else ''} diverge"
    )


def render(divergence: Divergence, only_divergent: bool = False) -> str:
    """The side-by-side report as plain text (see ``render_lines``)."""
    return "\n".join(text for text, _ in iter_lines(divergence, only_divergent))
