"""Build and run generated C nodes in tests: the host's gcc, and a Cortex-M4F under QEMU."""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

from etobs.codegen.c_node import generate_node, write_node
from etobs.codegen.vectors import node_vectors, write_vectors
from etobs.runtime.packet import derive_key

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
#: Every generated file must build without a warning as strict C99.
CFLAGS = ["-std=c99", "-O2", "-Wall", "-Wextra", "-pedantic", "-Werror"]
#: A Cortex-M4F (single-precision FPU) for QEMU's mps2-an386, with semihosting.
ARM_FLAGS = ["-mcpu=cortex-m4", "-mthumb", "-mfpu=fpv4-sp-d16", "-mfloat-abi=hard", "--specs=rdimon.specs"]
QEMU = [
    "qemu-system-arm",
    "-M",
    "mps2-an386",
    "-cpu",
    "cortex-m4",
    "-nographic",
    "-monitor",
    "none",
    "-serial",
    "none",
]
SECRET = b"etobs codegen test secret, 32 b"
SESSION = 1.7e9


def has_arm() -> bool:
    return shutil.which("arm-none-eabi-gcc") is not None and shutil.which("qemu-system-arm") is not None


def module(spec, period, folder: Path, *, node=0, n_values=1, profile="float64"):
    mod = generate_node(spec, period, node=node, n_values=n_values, profile=profile, name="test")
    write_node(mod, folder)
    return mod


def vectors(spec, period, y, folder: Path, *, node=0):
    vec = node_vectors(spec, period, node=node, key=derive_key(SECRET, node), session=SESSION, samples=y)
    return vec, write_vectors(vec, folder / "vectors.txt")


def build(folder: Path, main: str = "etobs_vectors.c", out: str = "run", extra=()) -> Path:
    exe = folder / out
    sources = [str(folder / main), str(folder / "etobs_node.c"), str(folder / "etobs_sha256.c")]
    subprocess.run(["gcc", *CFLAGS, *extra, "-I", str(folder), "-o", str(exe), *sources, "-lm"], check=True)
    return exe


def build_arm(folder: Path, main: str = "etobs_vectors.c", out: str = "run.elf", extra=()) -> Path:
    elf = folder / out
    q = HERE / "qemu"
    sources = [
        str(q / "startup.c"),
        str(folder / main),
        str(folder / "etobs_node.c"),
        str(folder / "etobs_sha256.c"),
    ]
    cmd = ["arm-none-eabi-gcc", *CFLAGS, *ARM_FLAGS, "-fstack-usage", *extra, "-I", str(folder)]
    cmd += ["-T", str(q / "mps2_an386.ld"), "-o", str(elf), *sources, "-lm"]
    subprocess.run(cmd, check=True, cwd=folder)
    return elf


def run_qemu(elf: Path, *args: str, icount: bool = False, timeout: float = 600) -> str:
    arg = ",".join(["arg=" + elf.name, *(f"arg={a}" for a in args)])
    cmd = [
        *QEMU,
        *(["-icount", "shift=0"] if icount else []),
        "-semihosting-config",
        f"enable=on,target=native,{arg}",
    ]
    out = subprocess.run(
        [*cmd, "-kernel", str(elf)], capture_output=True, text=True, timeout=timeout, cwd=elf.parent
    )
    return out.stdout + out.stderr


def figures(text: str) -> dict[str, float]:
    """The ``key=value`` figures of a runner's summary line."""
    return {k: float(v) for k, v in re.findall(r"(\w+)=([-+0-9.e]+)", text)}


def replay(exe: Path, vec_file: Path, tolerance: float = 0.0) -> tuple[int, dict[str, float]]:
    out = subprocess.run(
        [str(exe), str(vec_file), repr(tolerance)], capture_output=True, text=True, timeout=600
    )
    return out.returncode, figures(out.stdout + out.stderr)
