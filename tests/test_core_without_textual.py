import subprocess
import sys

from tests.conftest import REPO


def test_servant_core_imports_without_textual():
    # rich is not checked: scikit-learn imports it by itself when it is installed
    code = (
        "import importlib, pkgutil, sys, servant_core\n"
        "for m in pkgutil.walk_packages(servant_core.__path__, 'servant_core.'):\n"
        "    importlib.import_module(m.name)\n"
        "bad = sorted(n for n in sys.modules if n.split('.')[0] in ('textual', 'servant_tui'))\n"
        "print(len([n for n in sys.modules if n.startswith('servant_core')]), bad)\n"
        "sys.exit(1 if bad else 0)\n"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO)
    assert result.returncode == 0, result.stdout + result.stderr
    assert int(result.stdout.split()[0]) > 10  # the walk really imported the modules


# the bench scripts import these first; each must import on its own, with nothing before it
# (the scene library once imported the recognisers, whose registry imports the library back)
FIRST_IMPORTS = ("servant_core.library", "servant_core.capture", "servant_core.recognisers")


def test_core_modules_import_first_without_a_cycle():
    for name in FIRST_IMPORTS:
        result = subprocess.run(
            [sys.executable, "-c", f"import {name}"], capture_output=True, text=True, cwd=REPO
        )
        assert result.returncode == 0, f"import {name}: {result.stderr[-400:]}"
