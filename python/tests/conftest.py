"""Shared fixtures: the `sysid` binary of the same workspace, and small data sets."""

import os
import pathlib
import subprocess

import pytest

import sysid_mpf as sm

ROOT = pathlib.Path(__file__).resolve().parents[2]


def sysid_binary() -> pathlib.Path:
    """`sysid` built from this workspace (`cargo build --release`), or $SYSID_BIN."""
    path = pathlib.Path(os.environ.get("SYSID_BIN", ROOT / "target" / "release" / "sysid"))
    if not path.is_file():
        pytest.fail(
            f"{path} not found: build it with `cargo build --release --bin sysid` "
            "(or set SYSID_BIN); the equality tests compare the package with it"
        )
    return path


@pytest.fixture(scope="session")
def sysid():
    binary = sysid_binary()

    def call(*args, check=True):
        p = subprocess.run(
            [str(binary), *map(str, args)],
            capture_output=True,
            text=True,
            stdin=subprocess.DEVNULL,
        )
        if check and p.returncode != 0:
            raise AssertionError(f"sysid {' '.join(map(str, args))} failed:\n{p.stderr}")
        return p

    return call


@pytest.fixture(scope="session")
def short_data():
    """The paper's building under El Centro × 3, the first 3 s (300 steps)."""
    return sm.simulate(duration=3.0, seed=11)


@pytest.fixture(scope="session")
def short_dir(short_data, tmp_path_factory):
    d = tmp_path_factory.mktemp("data") / "paper-3s"
    short_data.write(d)
    return d


def cli_error(p) -> str:
    """The message `sysid` printed for its error (`Error: ...` to the end of stderr)."""
    assert p.returncode != 0, p.stderr
    at = p.stderr.index("Error: ")
    text = p.stderr[at + len("Error: ") :]
    assert text.endswith("\n")
    return text[:-1]
