"""The generated C on a Cortex-M4F under QEMU (mps2-an386, semihosting): the same vectors pass.

Needs Debian's gcc-arm-none-eabi, libnewlib-arm-none-eabi and qemu-system-arm (``make
embedded`` installs them, about 80 s, and runs these tests); skipped without them. The
float64 profile runs in software double precision there (the M4F's FPU is single), so
this also checks that newlib's soft-float ``sqrt`` rounds as glibc's does.
"""

from __future__ import annotations

import subprocess

import pytest

from etobs.examples.robot_arm import X0_PAPER, robot_arm
from etobs.runtime.replay import sample_outputs
from tests.codegen.cnode import build_arm, figures, has_arm, module, run_qemu, vectors

pytestmark = [
    pytest.mark.embedded,
    pytest.mark.skipif(
        not has_arm(), reason="needs arm-none-eabi-gcc and qemu-system-arm: run `make embedded`"
    ),
]

#: The call chain of a sample that sends: its frames add up to the node's stack use.
CHAIN = (
    "etobs_node_sample",
    "emit",
    "etobs_encode",
    "etobs_hmac_sha256",
    "etobs_sha256_final",
    "etobs_sha256_update",
)


def stack_use(folder) -> dict[str, int]:
    """Each function's frame in bytes, from gcc's -fstack-usage files."""
    out = {}
    for su in folder.glob("*.su"):
        for line in su.read_text().splitlines():
            where, size, _ = line.split("\t")
            out[where.rsplit(":", 1)[-1]] = int(size)
    return out


@pytest.mark.parametrize("profile", ["float64", "float32"])
def test_a_cortex_m4f_replays_1e5_robot_arm_samples_as_the_python_sensor(tmp_path, profile):
    _, y = sample_outputs(robot_arm(), list(X0_PAPER), 100.0, 0.001)
    spec = robot_arm().nodes[0].rule.sensor_spec()
    module(spec, 0.001, tmp_path, profile=profile)
    vec, path = vectors(spec, 0.001, y[:, [0]], tmp_path)
    elf = build_arm(tmp_path)
    got = figures(run_qemu(elf, path.name, "1e-4"))
    assert (
        got["samples"] == 100_001 and got["packets_differ"] == 0 and got["transmissions"] == vec.transmissions
    )
    if profile == "float64":
        assert got["decisions_equal"] == got["eta_equal"] == 100_001
    else:
        assert got["worst_margin"] <= 1e-4 and got["max_eta_drift"] <= 1e-4
    frames = stack_use(tmp_path)
    stack = sum(frames[f] for f in CHAIN)
    objs = []
    for src in ("etobs_node.c", "etobs_sha256.c"):
        obj = tmp_path / src.replace(".c", ".o")
        flags = [
            "-std=c99",
            "-O2",
            "-mcpu=cortex-m4",
            "-mthumb",
            "-mfpu=fpv4-sp-d16",
            "-mfloat-abi=hard",
            "-c",
        ]
        subprocess.run(["arm-none-eabi-gcc", *flags, "-o", str(obj), str(tmp_path / src)], check=True)
        objs.append(str(obj))
    size = subprocess.run(["arm-none-eabi-size", *objs], capture_output=True, text=True, check=True).stdout
    print(
        f"\n{profile}: {got}\narm-none-eabi-size (-O2):\n{size}stack of a sample that sends: {stack} bytes {frames}"
    )
    assert 0 < stack < 2048
