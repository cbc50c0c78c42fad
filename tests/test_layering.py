"""The layering rule: the method's core never imports Drake."""

import subprocess
import sys


def test_core_and_eval_import_without_drake():
    code = (
        "import pkgutil, importlib, sys\n"
        "import stucco_drake.core as core, stucco_drake.eval as ev\n"
        "for package in (core, ev):\n"
        "    for info in pkgutil.walk_packages(package.__path__, package.__name__ + '.'):\n"
        "        importlib.import_module(info.name)\n"
        "print(sorted(m for m in sys.modules if m.split('.')[0] == 'pydrake'))\n"
    )
    result = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    )
    assert result.stdout.strip() == "[]", result.stdout
