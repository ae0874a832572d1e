"""The catalogue at scale: 100,000 synthetic runs in 20 campaigns recorded in batches, then
the queries a dashboard and a user make, timed (SQLite by default; ``--url`` for PostgreSQL):
the campaign list, one campaign's runs, a range query across campaigns, the changes since a
seq (the second call of each: the first imports pandas). Prints the figures, with the
machine's load average and cores, and writes ``benchmarks/catalogue_scale.json``.

    python benchmarks/catalogue_scale.py [--runs 100000] [--url postgresql+psycopg://...]
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path
from typing import Any

from nematic_solids.sweep.catalogue import RunRow, open_catalogue

HERE = Path(__file__).resolve().parent


def rows(n: int, campaigns: int) -> list[RunRow]:
    out = []
    for i in range(n):
        c = i % campaigns
        a = round(0.1 * (1 + (i // campaigns) % 20), 3)
        out.append(
            RunRow(
                run_id=f"{i:016x}",
                campaign=f"c{c:02d}",
                status="ok" if i % 50 else "failed",
                reason=None if i % 50 else "nan",
                seed=(i // (campaigns * 20)) % 50,
                path=f"c{c:02d}/runs/{i:016x}.nc",
                t_final=300.0,
                wall_time=10.0,
                parameters={"K": [1e-5, 5e-5, 1e-4][c % 3], "chi": 10.0, "B": 0.5},
                numerics={"resolution": [128, 256][c % 2], "t_final": 300.0},
                scalars={"sigma2_S": 1e-3 * (i % 97), "lambda": 0.1},
                coords={"alpha_minus_B": a},
            )
        )
    return out


def timed(f):  # type: ignore[no-untyped-def]
    t0 = time.perf_counter()
    out = f()
    return out, time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=100_000)
    ap.add_argument("--url", default=None)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        cat = open_catalogue(args.url, root=root) if args.url else open_catalogue(root)
        data = rows(args.runs, 20)
        batch = 2000
        t0 = time.perf_counter()
        for k in range(0, len(data), batch):
            cat.record(data[k : k + batch])
        write = time.perf_counter() - t0
        seq = cat.last_seq()
        cat.record(data[:50])  # 50 runs updated: a poll's worth
        figures: dict[str, Any] = {
            "runs": args.runs,
            "backend": cat.db.dialect,
            "write_s": write,
            "write_runs_per_s": args.runs / write,
        }
        for name, f in {
            "campaigns_s": lambda: cat.campaigns(),
            "runs_of_one_campaign_s": lambda: cat.runs(campaign="c07"),
            "runs_where_s": lambda: cat.runs(
                where={"K": 1e-5, "alpha_minus_B": (0.5, 0.7), "resolution": 256}
            ),
            "changes_since_s": lambda: cat.changes(seq),
        }.items():
            f()  # the first call imports pandas: the second is timed
            out, seconds = timed(f)
            figures[name] = seconds
            figures[name[: -len("_s")] + "_rows"] = len(out)
        cat.close()
    figures["load_average_1min"] = os.getloadavg()[0]  # this machine is shared: read with it
    figures["cores"] = os.cpu_count()
    for key, v in figures.items():
        print(f"{key}: {v:.4g}" if isinstance(v, float) else f"{key}: {v}")
    (HERE / "catalogue_scale.json").write_text(json.dumps(figures, indent=2) + "\n")


if __name__ == "__main__":
    main()
