"""Table 3 with all three planners on eq. (12), without running DDRRT* twice: DDRRT*'s runs do not
depend on the baselines' objective (run i, algorithm a is seeded from (seed, i, a) only), so its rows
come from the paper-setting campaign, restricted to the runs the eq. (12) campaign finished.

Run: python docs/experiments/ddrrt/combine_tables.py PAPER_RUNS.csv[.gz] EQ12_RUNS.csv[.gz] OUT_PREFIX TITLE
"""

import gzip
import shutil
import sys
import tempfile
from pathlib import Path

from hil import experiment


def rows(path: str):
    p = Path(path)
    if p.suffix == ".gz":
        with gzip.open(p, "rb") as src, tempfile.NamedTemporaryFile(suffix=".csv", delete=False) as dst:
            shutil.copyfileobj(src, dst)
        p = Path(dst.name)
    return experiment.read_runs_csv(p)


paper, eq12, out, title = sys.argv[1], sys.argv[2], Path(sys.argv[3]), sys.argv[4]
base = [r for r in rows(eq12) if r["algorithm"] in ("rrt-star", "informed-rrt-star")]
done = {r["run"] for r in base if r["algorithm"] == "rrt-star"} & {
    r["run"] for r in base if r["algorithm"] == "informed-rrt-star"
}
dd_all = [r for r in rows(paper) if r["algorithm"] == "ddrrt-star"]
done &= {r["run"] for r in dd_all}
base = [r for r in base if r["run"] in done]
dd = [r for r in dd_all if r["run"] in done]
table = experiment.table3(base + dd)
experiment.write_table_csv(out.with_suffix(".csv"), table)
experiment.write_table_md(
    out.with_suffix(".md"), table, f"{title}: {len(done)} runs per algorithm (the runs both campaigns finished)"
)
print(experiment.table_markdown(table, title))
