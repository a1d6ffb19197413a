"""The README's Python example (`examples/identify_building.py`): shown in full, it runs, and its
figure tells every line apart (matplotlib cycles 10 colours: 13 lines in one panel reuse 3)."""

import pathlib
import runpy

import matplotlib

matplotlib.use("Agg")  # no display: the example only writes a PNG

import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.colors import to_hex  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "examples" / "identify_building.py"


def test_readme_shows_the_example_in_full():
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    example = EXAMPLE.read_text(encoding="utf-8")
    assert f"```python\n{example}```" in readme, "README's example differs from the file"


def test_example_runs_and_tells_every_line_apart(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    plt.close("all")
    names = runpy.run_path(str(EXAMPLE), run_name="__main__")
    assert (tmp_path / "theta_over_time.png").stat().st_size > 0
    drawn = []
    for number in plt.get_fignums():
        for ax in plt.figure(number).axes:
            lines = [ln for ln in ax.get_lines() if not ln.get_label().startswith("_")]
            looks = [(to_hex(ln.get_color()), ln.get_linestyle()) for ln in lines]
            labels = [ln.get_label() for ln in lines]
            # Within a panel, no two lines share colour and style.
            assert len(set(looks)) == len(looks), f"lines {labels} share a look: {looks}"
            drawn += labels
    plt.close("all")
    # Every parameter is drawn, once.
    assert sorted(drawn) == sorted(names["result"].param_names)
