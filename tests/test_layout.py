"""The repository installs as ONE import package with four subpackages."""

import ast
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

import osmobulge

ROOT = Path(__file__).resolve().parents[1]
SUBPACKAGES = ["modeling", "imaging", "experiments", "plugins"]


@pytest.mark.parametrize("name", SUBPACKAGES)
def test_subpackages_import_under_osmobulge(name):
    mod = __import__(f"osmobulge.{name}", fromlist=["_"])
    assert Path(mod.__file__).resolve().parent == ROOT / name


@pytest.mark.parametrize("name", SUBPACKAGES)
def test_folders_are_not_top_level_import_names(name, tmp_path):
    # run from an empty folder so the repository is not on sys.path
    code = f"import importlib.util, sys; sys.exit(0 if importlib.util.find_spec({name!r}) is None else 1)"
    assert subprocess.run([sys.executable, "-c", code], cwd=tmp_path).returncode == 0


def _imports(path: Path):
    tree = ast.parse(path.read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            yield from (a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module:
            yield node.module


@pytest.mark.parametrize(
    ("package", "forbidden"),
    [
        ("modeling", ["osmobulge.imaging", "osmobulge.experiments", "osmobulge.plugins"]),
        ("imaging", ["osmobulge.experiments", "osmobulge.plugins"]),
        ("experiments", ["osmobulge.plugins"]),
    ],
)
def test_nothing_imports_upward(package, forbidden):
    for path in (ROOT / package).rglob("*.py"):
        for name in _imports(path):
            assert not any(name == f or name.startswith(f + ".") for f in forbidden), f"{path}: imports {name}"


def test_qt_only_in_plugins():
    for package in ["modeling", "imaging", "experiments"]:
        for path in (ROOT / package).rglob("*.py"):
            for name in _imports(path):
                assert name.split(".")[0] not in {"qtpy", "PyQt5", "PyQt6", "PySide6", "napari"}, path


def test_cli_version():
    out = subprocess.run([sys.executable, "-m", "osmobulge.experiments.cli", "--version"],
                         capture_output=True, text=True, check=True)
    assert out.stdout.strip() == f"osmobulge {osmobulge.__version__}"


@pytest.mark.slow
def test_wheel_contains_one_package_and_imports(tmp_path):
    wheel_dir = tmp_path / "wheel"
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(wheel_dir), str(ROOT)],
        check=True,
    )
    (wheel,) = wheel_dir.glob("osmobulge-*.whl")
    names = zipfile.ZipFile(wheel).namelist()
    tops = {n.split("/")[0] for n in names if not n.split("/")[0].endswith((".dist-info", ".data"))}
    assert tops == {"osmobulge"}
    for sub in SUBPACKAGES:
        assert f"osmobulge/{sub}/__init__.py" in names
    assert not any("/tests/" in n or n.startswith("tests/") for n in names)
    assert "osmobulge/plugins/napari.yaml" in names
    site = tmp_path / "site"
    subprocess.run([sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--target", str(site), str(wheel)],
                   check=True)
    code = ("import osmobulge, osmobulge.modeling as m; "
            "print(osmobulge.__file__); print(round(m.locking_volume(m.materials.PDMS), 2))")
    out = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True,
                         env={"PYTHONPATH": str(site), "PATH": "/usr/bin:/bin",
                              "OSMOBULGE_CACHE_DIR": str(tmp_path / "cache")}, check=True)
    file_line, lock = out.stdout.split()
    assert file_line.startswith(str(site))
    assert lock == "7.21"
