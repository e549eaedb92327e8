"""The generated C node: time per sample on the host, instructions per sample on a Cortex-M4F.

Run: ``python benchmarks/bench_c_node.py [--quick]``.

The robot arm's node 0 (the paper's rule, ``T = 1 ms``, 100 s from the paper's ``x0``:
100,001 samples; ``--quick``: 20,000), written by ``etobs codegen c`` in both profiles:

* **host**: ``benchmarks/c_node_bench.c`` compiled with the system's ``gcc -O2`` runs the
  node over the samples held in memory; nanoseconds per sample, against the Python
  sensor node (:class:`etobs.runtime.sensor.SensorNode`) on the same samples, measured in
  the same run (the ratio is the figure; the machine is shared);
* **Cortex-M4F** (when ``arm-none-eabi-gcc`` and ``qemu-system-arm`` are installed: ``make
  embedded``): the same program under QEMU's mps2-an386 with ``-icount shift=0``, the
  SysTick counter read around each sample and calibrated by a loop of 200,000
  instructions: instructions per sample (QEMU counts instructions, not cycles); the code
  size of the node's two object files (``arm-none-eabi-size``, ``-O2``) and the stack of a
  sample that sends (``-fstack-usage``, summed along its call chain).
"""

from __future__ import annotations

import argparse
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT))

from tests.codegen.cnode import ARM_FLAGS, QEMU  # noqa: E402
from tests.codegen.test_embedded import CHAIN, stack_use  # noqa: E402

from etobs.codegen.c_node import generate_node, write_node  # noqa: E402
from etobs.codegen.vectors import node_vectors, write_vectors  # noqa: E402
from etobs.examples.robot_arm import X0_PAPER, robot_arm  # noqa: E402
from etobs.runtime.packet import derive_key  # noqa: E402
from etobs.runtime.replay import sample_outputs  # noqa: E402
from etobs.runtime.sampled_rule import SampledRule  # noqa: E402
from etobs.runtime.sensor import SensorNode  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="20,000 samples, fewer repeats")
    args = parser.parse_args()
    n = 20_000 if args.quick else 100_001
    repeats = 5 if args.quick else 20
    pb = robot_arm()
    _, y = sample_outputs(pb, list(X0_PAPER), (n - 1) * 0.001, 0.001)
    spec = pb.nodes[0].rule.sensor_spec()
    key = derive_key(b"bench", 0)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        vec = node_vectors(spec, 0.001, node=0, key=key, session=1.7e9, samples=y[:, [0]])
        write_vectors(vec, folder / "vectors.txt")
        # the Python sensor node on the same samples (one pass: it is the slow one)
        sink: list[bytes] = []
        node = SensorNode(0, key, SampledRule(spec, 0.001), sink.append, session=1.7e9)
        t0 = time.perf_counter()
        for k, row in enumerate(y[:, [0]].tolist()):
            node.sample(k * 0.001, row)
        py_ns = 1e9 * (time.perf_counter() - t0) / len(y)
        print(f"samples: {len(y)}, transmissions: {vec.transmissions}")
        print(f"python sensor node: {py_ns:.0f} ns per sample")
        for profile in ("float64", "float32"):
            sub = folder / profile
            write_node(generate_node(spec, 0.001, node=0, n_values=1, profile=profile, name="robot_arm"), sub)
            exe = sub / "bench"
            src = [str(HERE / "c_node_bench.c"), str(sub / "etobs_node.c"), str(sub / "etobs_sha256.c")]
            cmd = [
                "gcc",
                "-std=c99",
                "-O2",
                "-DETOBS_HOST_CLOCK",
                "-I",
                str(sub),
                "-o",
                str(exe),
                *src,
                "-lm",
            ]
            subprocess.run(cmd, check=True)
            out = subprocess.run(
                [str(exe), str(folder / "vectors.txt"), str(repeats)], capture_output=True, text=True
            )
            ns = float(re.search(r"ns_per_sample=([0-9.]+)", out.stdout).group(1))
            state = re.search(r"state_bytes=(\d+)", out.stdout).group(1)
            print(
                f"host C, {profile}: {ns:.1f} ns per sample ({py_ns / ns:.0f}x the Python node), state {state} bytes"
            )
            if shutil.which("arm-none-eabi-gcc") and shutil.which("qemu-system-arm"):
                arm(sub, folder / "vectors.txt", profile, repeats=1)
            else:
                print(
                    f"Cortex-M4F, {profile}: skipped (no arm-none-eabi-gcc / qemu-system-arm; `make embedded`)"
                )


def arm(sub: Path, vectors: Path, profile: str, repeats: int) -> None:
    q = ROOT / "tests" / "codegen" / "qemu"
    elf = sub / "bench.elf"
    src = [
        str(q / "startup.c"),
        str(HERE / "c_node_bench.c"),
        str(sub / "etobs_node.c"),
        str(sub / "etobs_sha256.c"),
    ]
    cmd = [
        "arm-none-eabi-gcc",
        "-std=c99",
        "-O2",
        *ARM_FLAGS,
        "-fstack-usage",
        "-DETOBS_SYSTICK",
        "-I",
        str(sub),
    ]
    subprocess.run([*cmd, "-T", str(q / "mps2_an386.ld"), "-o", str(elf), *src, "-lm"], check=True, cwd=sub)
    semi = f"enable=on,target=native,arg=bench,arg={vectors},arg={repeats}"
    run = [*QEMU, "-icount", "shift=0", "-semihosting-config", semi, "-kernel", str(elf)]
    out = subprocess.run(run, capture_output=True, text=True, timeout=600).stdout
    ticks = float(re.search(r"ticks_per_sample=([0-9.]+)", out).group(1))
    state = re.search(r"state_bytes=(\d+)", out).group(1)
    per_tick = 200_000 / float(re.search(r"calibration_ticks=(\d+)", out).group(1))
    objs = []
    for name in ("etobs_node.c", "etobs_sha256.c"):
        obj = sub / name.replace(".c", ".o")
        subprocess.run(
            ["arm-none-eabi-gcc", "-std=c99", "-O2", *ARM_FLAGS[:4], "-c", "-o", str(obj), str(sub / name)],
            check=True,
        )
        objs.append(obj)
    sizes = subprocess.run(
        ["arm-none-eabi-size", *map(str, objs)], capture_output=True, text=True, check=True
    ).stdout
    text = sum(int(line.split()[0]) for line in sizes.splitlines()[1:])
    frames = stack_use(sub)
    stack = sum(frames[f] for f in CHAIN)
    print(
        f"Cortex-M4F (QEMU), {profile}: {ticks * per_tick:.0f} instructions per sample "
        f"({ticks:.2f} SysTick ticks, {per_tick:.1f} instructions per tick); code {text} bytes "
        f"(etobs_node.o + etobs_sha256.o, -O2); stack of a sample that sends {stack} bytes; state {state} bytes"
    )


if __name__ == "__main__":
    main()
