"""Two trees' benchmark figures side by side: the JSON of ``bench_configurations.py`` and
``bench_reference.py`` run alternately on an old and a new tree (each several rounds), as one
markdown table of new/old time ratios (medians over the rounds).

    .venv/bin/python benchmarks/compare_trees.py --old conf_old_*.json --new conf_new_*.json
    .venv/bin/python benchmarks/compare_trees.py --old ref_old_*.json --new ref_new_*.json

Rows of ``bench_configurations``: (configuration, mesh, ranks) with the configuration's and its
base's step times and their ratio (timed in alternating batches of one process); of ``bench_reference``: (implementation, ranks) with fempm's step time and its
ratio to the numba kernel timed in the same run (which takes out the machine's drift).
"""

from __future__ import annotations

import argparse
import json
import statistics
from pathlib import Path


def figures(paths: list[Path]) -> dict[tuple, dict[str, list[float]]]:
    """(row key) -> {figure: [values over the files]}."""
    out: dict[tuple, dict[str, list[float]]] = {}
    for path in paths:
        for row in json.loads(path.read_text())["rows"]:
            if "config" in row:
                key = (row["config"], row["mesh"], row["ranks"])
                values = {"step [ms]": 1e3 * row["t_s"], "base step [ms]": 1e3 * row["t_base_s"],
                          "time / base's": row["ratio"]}
            elif row["impl"].startswith("fempm"):
                key = (row["impl"], "", row["ranks"])
                values = {"step [ms]": 1e3 * row["t_step_s"], "time / numba's": 1.0 / row["vs"]["numba"]}
            else:
                continue
            for name, v in values.items():
                out.setdefault(key, {}).setdefault(name, []).append(v)
    return out


def main(argv: list[str] | None = None) -> str:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--old", type=Path, nargs="+", required=True)
    ap.add_argument("--new", type=Path, nargs="+", required=True)
    a = ap.parse_args(argv)
    old, new = figures(a.old), figures(a.new)
    names = list(next(iter(old.values())))
    head = ["row", "ranks", *(f"{n} old / new" for n in names), *(f"new/old {n}" for n in names)]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    ratios = {n: [] for n in names}
    for key in old:
        if key not in new:
            continue
        cells = [" ".join(k for k in key[:2] if k), str(key[2])]
        med = {n: (statistics.median(old[key][n]), statistics.median(new[key][n])) for n in names}
        cells += [f"{o:.3g} / {w:.3g}" for o, w in med.values()]
        cells += [f"{w / o:.3f}" for o, w in med.values()]
        for n, (o, w) in med.items():
            ratios[n].append(w / o)
        lines.append("| " + " | ".join(cells) + " |")
    lines.append("")
    lines += [f"median new/old {n}: {statistics.median(r):.3f} (range {min(r):.3f}-{max(r):.3f}, {len(r)} rows)"
              for n, r in ratios.items()]
    text = "\n".join(lines)
    print(text)
    return text


if __name__ == "__main__":
    main()
