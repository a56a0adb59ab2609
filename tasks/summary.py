"""Run summaries: RUN_DIR/run.json and markdown tables for Prefect artifacts."""
from __future__ import annotations

import math
from pathlib import Path

import pandas as pd
from prefect import task

from aerosid.io import write_json_atomic


def markdown_table(frame: pd.DataFrame, floatfmt: str = ".4g") -> str:
    def cell(v) -> str:
        if isinstance(v, float):
            return "" if math.isnan(v) else format(v, floatfmt)
        return str(v)

    head = "| " + " | ".join(frame.columns) + " |"
    rule = "|" + "|".join("---" for _ in frame.columns) + "|"
    rows = ["| " + " | ".join(cell(v) for v in row) + " |" for row in frame.itertuples(index=False)]
    return "\n".join([head, rule, *rows])


@task(name="write-run-summary", retries=2, retry_delay_seconds=0.2)
def write_run_summary_task(run_dir: str, summary: dict) -> str:
    return str(write_json_atomic(summary, Path(run_dir) / "run.json"))
