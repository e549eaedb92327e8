import subprocess
import sys

import etobs


def test_import_does_not_load_matplotlib():
    code = "import sys, etobs, etobs.examples; print('matplotlib' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_numerics_do_not_import_plotting_io_or_cli():
    code = (
        "import sys, etobs.hybrid, etobs.estimation, etobs.model, etobs.examples;"
        "print(sorted(m for m in sys.modules if m.startswith(('etobs.plot', 'etobs.cli', 'matplotlib'))))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_public_api_is_exported():
    for name in etobs.__all__:
        assert hasattr(etobs, name), name
    assert etobs.__version__ == "0.1.0"
