"""Start-up: `import sysid_mpf` and a run that only writes its record do not load numpy (about
0.1 s of a new process, docs/python.md); the first array asked for loads it."""

import json
import subprocess
import sys

SCRIPT = """
import json, sys
import sysid_mpf as sm
seen = {"after import": "numpy" in sys.modules}
r = sm.identify(sm.load_dataset(sys.argv[1]), algorithm="bootstrap", particles=20, seed=1,
                out=sys.argv[2])
seen["after identify"] = "numpy" in sys.modules
theta = r.theta_val
seen["after theta_val"] = "numpy" in sys.modules
seen["theta_val"] = [float(x) for x in theta]
print(json.dumps(seen))
"""


def test_numpy_is_loaded_only_when_an_array_is_asked_for(short_dir, tmp_path):
    out = tmp_path / "run.json"
    p = subprocess.run(
        [sys.executable, "-c", SCRIPT, str(short_dir), str(out)],
        capture_output=True,
        text=True,
        stdin=subprocess.DEVNULL,
    )
    assert p.returncode == 0, p.stderr
    seen = json.loads(p.stdout)
    assert seen["after import"] is False
    assert seen["after identify"] is False
    assert seen["after theta_val"] is True
    # The record written is the run's, and the array the same numbers.
    record = json.loads(out.read_text())
    assert seen["theta_val"] == record["theta_val"]
