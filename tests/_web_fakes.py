"""A fake job worker for the web tests: no simulation, a few states over about a second.

It is the worker body of :class:`undulate.interfaces.web.jobs.JobManager` (the job folder as
a string), so the queue, progress, cancel and downloads are tested without the engine.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

from undulate.interfaces.web.jobs import _write_state, read_state


def fake_job(folder: str) -> None:
    f = Path(folder)
    case = json.loads((f / "case.json").read_text())
    st = read_state(f)
    seconds = 0.2 * case["imperfection"]["seed"]  # the tests set the run time through seed
    st.update(status="running", started=time.time(), stage="fake")
    _write_state(f, st)
    for k in range(5):
        time.sleep(seconds / 5)
        st["progress"] = (k + 1) / 5
        _write_state(f, st)
    res = f / "result"
    res.mkdir()
    (res / "metrics.json").write_text(json.dumps({"n": 3, "rods": len(case["rods"]["segments"])}))
    st.update(status="done", finished=time.time(), metrics={"n": 3, "family": "waves"})
    _write_state(f, st)
