"""``meshgen.run.resources.available_memory``: on Linux MemAvailable read from /proc/meminfo, the
figure psutil reports, without importing psutil."""

from __future__ import annotations

import sys

import pytest

from meshgen.run import resources

psutil = pytest.importorskip("psutil")
linux = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc/meminfo: Linux only")


def fake_meminfo(folder, text: str):
    (folder / "meminfo").write_text(text)
    return str(folder / "meminfo")


@linux
@pytest.mark.parametrize(
    "fields",
    [
        {"MemTotal:": 16_000_000, "MemFree:": 1_000_000, "MemAvailable:": 9_500_000},
        {"MemTotal:": 16_000_000, "MemFree:": 1_000_000},  # an old kernel: no MemAvailable
        {"MemTotal:": 16_000_000, "MemFree:": 1_000_000, "MemAvailable:": 0},  # psutil's estimate then
        {"MemTotal:": 16_000_000, "MemFree:": 1_000_000, "MemAvailable:": 20_000_000},  # a container's distorted figure
    ],
)
def test_available_memory_is_psutils_figure(tmp_path, monkeypatch, fields):
    real = open("/proc/meminfo").read().splitlines()
    kept = [line for line in real if line.split()[0] not in ("MemTotal:", "MemFree:", "MemAvailable:")]
    text = "\n".join([f"{name} {value} kB" for name, value in fields.items()] + kept) + "\n"
    monkeypatch.setattr(resources, "MEMINFO", fake_meminfo(tmp_path, text))
    monkeypatch.setattr(psutil, "PROCFS_PATH", str(tmp_path))
    assert resources.available_memory() == psutil.virtual_memory().available
    assert (resources._meminfo_available() is not None) == (0 < fields.get("MemAvailable:", 0) <= fields["MemTotal:"])


@linux
def test_available_memory_does_not_import_psutil():
    import subprocess

    code = "import sys\nfrom meshgen.run.resources import available_memory\nassert available_memory() > 0\nprint('psutil' in sys.modules)"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=True)
    assert done.stdout.strip() == "False"
