"""A batch on a dask client: every task submitted, results gathered as they finish, progress with an ETA.

A task whose worker died or that dask could not run is a failed row with dask's error: the batch goes on.
"""

from __future__ import annotations

import uuid
from collections.abc import Sequence
from typing import Any

from benchlab.batch.cluster import require_distributed
from benchlab.batch.tasks import FAILED, Job, Task, error_text, failed_row, run_task
from benchlab.progress import SILENT, Progress


def run_batch(client: Any, job: Job, tasks: Sequence[Task], progress: Progress = SILENT) -> list[dict]:
    """The rows of every task (see tasks.run_task), in the order they finished."""
    distributed = require_distributed()
    batch = uuid.uuid4().hex[:8]  # keys unique on a scheduler that outlives this batch
    futures = {client.submit(run_task, job, task, key=f"benchlab-{job.kind}-{batch}-{i}-{task.name}"): task
               for i, task in enumerate(tasks)}
    rows: list[dict] = []
    failed = 0
    with progress.task(f"batch {job.kind}", len(tasks), unit="task") as bar:
        for future in distributed.as_completed(futures):
            task = futures.pop(future)
            try:
                done = future.result()
            except Exception as exc:  # noqa: BLE001 - a lost worker or task is a row, never a lost batch
                done = [failed_row(task, ";".join(r.path for r in task.runs), f"dask: {error_text(exc)}")]
            future.release()
            rows.extend(done)
            failed += sum(row["status"] == FAILED for row in done)
            bar.advance()
            bar.note(f"{failed} failed")
    return rows
