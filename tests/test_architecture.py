"""The design card's boundaries: the core never imports Prefect; tasks and flows hold no maths."""
import ast
import pkgutil
import subprocess
import sys
from pathlib import Path

import aerosid

ROOT = Path(__file__).parents[1]


def test_importing_every_core_module_does_not_load_prefect():
    modules = [m.name for m in pkgutil.walk_packages(aerosid.__path__, "aerosid.")]
    code = "import importlib, sys\n" + "".join(f"importlib.import_module({m!r})\n" for m in modules) + \
        "print('prefect' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False", out.stdout


def test_tasks_and_flows_import_no_numerical_libraries():
    banned = {"numpy", "scipy", "statsmodels", "numba", "filterpy"}
    for folder in ("tasks", "flows"):
        for path in (ROOT / folder).glob("*.py"):
            tree = ast.parse(path.read_text())
            for node in ast.walk(tree):
                names = []
                if isinstance(node, ast.Import):
                    names = [a.name for a in node.names]
                elif isinstance(node, ast.ImportFrom) and node.module:
                    names = [node.module]
                for name in names:
                    assert name.split(".")[0] not in banned, f"{path.name} imports {name}"
