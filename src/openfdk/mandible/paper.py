"""The published Tables 1 and 2 of Andersen et al. (2017), for printing beside openfdk's.

Numbers transcribed from the paper (shared/reference/fdk-paper-andersen2017.txt,
"Table 1" and "Table 2"): per task × side × direction, mean ± SD over five cycles of
RMSD, r², Sprague–Geers M and P. Table 1: FDK and POP condyle kinematics vs measured
(RMSD in mm); Table 2: POP vs FDK TMJ reaction forces (RMSD in N; c = POP, m = FDK, so
M < 0 means the POP force is smaller, as in openfdk's Table 2). The paper's subject is
not openfdk's virtual subject: the comparison is of orders of magnitude and patterns,
not of values.
"""

from __future__ import annotations

from .tables import _HEADER, DIRECTIONS, METRICS, _cell, _number, task_title

__all__ = ["PAPER_TABLE1", "PAPER_TABLE2", "format_table2_with_paper", "paper_row"]

_TASKS = ("chewing", "open_close", "protrusion")
_ORDER = [(task, side, d) for task in _TASKS for side in ("left", "right") for d in DIRECTIONS]

# (RMSD, r², M, P) as (mean, sd) pairs, rows in _ORDER (paper's row order)
_T2 = """
4.71 0.46 0.46 0.10 0.12 0.10 0.18 0.02
12.5 1.44 0.14 0.09 0.35 0.21 0.51 0.01
5.67 0.37 0.89 0.03 -0.21 0.04 0.08 0.01
9.84 0.89 0.06 0.07 0.73 0.17 0.44 0.04
17.88 2.87 0.00 0.00 0.92 0.43 0.50 0.02
6.63 0.51 0.87 0.09 -0.20 0.04 0.09 0.02
7.49 2.44 0.95 0.03 0.48 0.18 0.04 0.01
18.69 12.25 0.37 0.32 -0.77 0.17 0.43 0.13
12.17 4.05 0.99 0.01 -0.23 0.07 0.02 0.01
19.29 5.42 0.09 0.13 3.34 2.66 0.19 0.03
24.7 5.96 0.23 0.30 -0.86 0.08 0.53 0.26
14.4 3.66 0.99 0.00 -0.25 0.07 0.03 0.01
0.75 0.13 0.64 0.21 -0.08 0.18 0.11 0.01
5.46 1.01 0.37 0.32 -0.93 0.03 0.34 0.11
3.25 0.25 0.73 0.19 -0.49 0.10 0.10 0.01
2.37 0.37 0.14 0.21 -0.08 0.23 0.34 0.05
5.14 1.14 0.14 0.08 -0.68 0.10 0.56 0.02
4.68 0.67 0.38 0.26 -0.51 0.07 0.15 0.04
"""
# FDK then POP, (RMSD, r², M, P) as (mean, sd) pairs
_T1 = """
0.79 0.06 0.99 0.00 0.00 0.01 0.05 0.01 0.57 0.03 0.99 0.00 0.00 0.01 0.04 0.00
0.98 0.07 0.70 0.13 0.00 0.00 0.01 0.00 0.74 0.04 0.03 0.03 -0.01 0.00 0.00 0.00
1.70 0.09 0.93 0.01 -0.03 0.02 0.22 0.02 0.63 0.07 0.98 0.01 -0.03 0.02 0.08 0.01
0.78 0.03 1.00 0.00 0.11 0.01 0.04 0.00 0.39 0.03 0.99 0.00 0.02 0.02 0.02 0.00
0.95 0.07 0.79 0.11 0.00 0.00 0.01 0.00 0.75 0.04 0.12 0.06 0.01 0.00 0.00 0.00
1.66 0.09 0.57 0.06 -0.06 0.03 0.14 0.01 0.48 0.10 0.96 0.02 -0.01 0.03 0.04 0.01
0.61 0.04 0.99 0.01 0.00 0.05 0.04 0.02 0.35 0.04 0.99 0.00 -0.01 0.03 0.03 0.01
0.48 0.10 0.30 0.13 0.01 0.00 0.00 0.01 0.27 0.03 0.21 0.05 0.00 0.00 0.00 0.00
1.25 0.15 0.92 0.08 0.13 0.20 0.16 0.07 0.47 0.06 0.99 0.00 -0.02 0.03 0.07 0.04
0.81 0.08 1.00 0.00 0.12 0.04 0.06 0.04 0.22 0.05 1.00 0.00 0.05 0.04 0.01 0.01
0.47 0.10 0.32 0.12 -0.01 0.00 0.00 0.00 0.28 0.03 0.14 0.11 0.00 0.00 0.00 0.00
1.41 0.06 0.85 0.12 -0.05 0.16 0.12 0.03 0.33 0.08 0.98 0.00 -0.08 0.05 0.02 0.00
0.59 0.07 0.99 0.00 -0.04 0.01 0.03 0.00 0.32 0.05 1.00 0.00 0.02 0.01 0.01 0.00
1.16 0.14 0.18 0.11 0.00 0.00 0.01 0.00 0.37 0.12 0.05 0.08 0.01 0.00 0.00 0.00
1.34 0.12 0.92 0.02 0.02 0.05 0.11 0.01 0.53 0.05 0.99 0.00 -0.04 0.02 0.04 0.01
0.88 0.08 0.99 0.00 0.07 0.01 0.04 0.01 0.21 0.02 1.00 0.00 0.00 0.00 0.01 0.00
1.16 0.14 0.18 0.12 0.00 0.00 0.01 0.00 0.37 0.11 0.06 0.10 -0.01 0.00 0.00 0.00
1.25 0.10 0.91 0.02 0.00 0.03 0.09 0.01 0.40 0.07 0.98 0.00 -0.05 0.03 0.02 0.00
"""


def _table(text, labels):
    out = {}
    for key, line in zip(_ORDER, text.strip().splitlines()):
        values = [float(v) for v in line.split()]
        row = {"task": key[0], "side": key[1], "direction": key[2]}
        for k, label in enumerate(labels):
            for j, name in enumerate(METRICS):
                row[f"{label}_{name}_mean"], row[f"{label}_{name}_sd"] = values[8 * k + 2 * j: 8 * k + 2 * j + 2]
        out[key] = row
    return out


#: (task, side, direction) → row in openfdk's row layout (labels "FDK", "POP"; RMSD mm)
PAPER_TABLE1 = _table(_T1, ("FDK", "POP"))
#: (task, side, direction) → row in openfdk's row layout (label "POP" vs FDK; RMSD N)
PAPER_TABLE2 = _table(_T2, ("POP",))


def paper_row(table, row) -> dict | None:
    """The paper's row matching an openfdk row's task kind, side and direction (None
    for a task the paper did not record)."""
    return table.get((row.get("kind", row["task"]), row["side"], row["direction"]))


def format_table2_with_paper(rows, kinds=None, decimals: int = 2) -> str:
    """openfdk's Table 2 (POP vs FDK) beside the paper's, one line per task × side ×
    direction, for the terminal; ``kinds``: task → task kind (for user-named tasks),
    default the task name. A last line gives both RMSD ranges."""
    width = 2 * decimals + 8
    names = " ".join(f"{_HEADER[n] + ('(N)' if n == 'RMSD' else ''):>{width}}" for n in METRICS)
    lines = [f"{'':<12}{'openfdk: POP vs FDK':^{len(names)}} | {'paper (Andersen et al. 2017)':^{len(names)}}",
             f"{'':<12}{names} | {names}"]
    task, ours, theirs = None, [], []
    for row in rows:
        if row["task"] != task:
            task = row["task"]
            lines.append(f"{task_title(task)} ({row['n_cycles']} cycles)")
        key = dict(row, kind=(kinds or {}).get(row["task"], row["task"]))
        paper = paper_row(PAPER_TABLE2, key)
        mine = " ".join(f"{_cell(row, 'POP', n, decimals):>{width}}" for n in METRICS)
        published = (" ".join(f"{_cell(paper, 'POP', n, decimals):>{width}}" for n in METRICS)
                     if paper else f"{'(not in the paper)':^{len(names)}}")
        lines.append(f"  {row['side']:<6}{row['direction']:<4}{mine} | {published}")
        ours.append(row["POP_RMSD_mean"])
        if paper:
            theirs.append(paper["POP_RMSD_mean"])
    mine_range = f"{_number(min(ours), decimals)}–{_number(max(ours), decimals)} N"
    paper_range = f"{_number(min(theirs), decimals)}–{_number(max(theirs), decimals)} N" if theirs else "-"
    lines.append(f"RMSD range: openfdk {mine_range}, paper {paper_range}")
    return "\n".join(lines) + "\n"
