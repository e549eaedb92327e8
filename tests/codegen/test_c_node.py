"""The generated C node against the Python sensor node (conformance vectors), built by the host's gcc.

Reference: :class:`etobs.runtime.sensor.SensorNode` with its sampled rule, fed the same
samples (:mod:`etobs.codegen.vectors`). ``float64``: every decision, every filter value
and every packet byte equal. ``float32``: decisions equal except within
:data:`FLOAT32_MARGIN` of the threshold (relative), the filter within
:data:`FLOAT32_DRIFT` (relative), packets equal where the decisions are.
"""

from __future__ import annotations

import hashlib
import hmac
import re
import subprocess
from pathlib import Path

import numpy as np
import pytest

from etobs.cli.main import main
from etobs.codegen.c_node import generate_node
from etobs.errors import InputError
from etobs.examples.robot_arm import X0_PAPER, robot_arm
from etobs.model import (
    Custom,
    DynamicRule,
    GeneralizedRule,
    Linear,
    PeriodicRule,
    Power,
    Quadratic,
    RelativeRule,
    StaticRule,
)
from etobs.runtime.replay import sample_outputs
from tests.codegen.cnode import HERE, build, module, replay, vectors
from tests.model.test_sampled import docs_model

#: How close to its threshold (relative, |g| / scale) a float32 node may decide otherwise.
FLOAT32_MARGIN = 1e-4
#: How far (relative to max(1, |eta|)) a float32 node's filter may drift from the float64 one.
FLOAT32_DRIFT = 1e-4


@pytest.fixture(scope="module")
def arm_samples():
    """The robot arm's outputs at 1 ms for 100 s from the paper's x0: 100,001 samples."""
    _, y = sample_outputs(robot_arm(), list(X0_PAPER), 100.0, 0.001)
    return y


@pytest.mark.parametrize("node", [0, 1])
def test_float64_packets_are_the_python_sensors_byte_for_byte_on_1e5_robot_arm_samples(
    tmp_path, arm_samples, node
):
    spec = robot_arm().nodes[node].rule.sensor_spec()
    module(spec, 0.001, tmp_path, node=node)
    vec, path = vectors(spec, 0.001, arm_samples[:, [node]], tmp_path, node=node)
    code, got = replay(build(tmp_path), path)
    assert code == 0, got
    assert got["samples"] == 100_001 == got["decisions_equal"] == got["eta_equal"]
    assert got["decision_mismatches"] == 0 and got["packets_differ"] == 0
    assert got["packets_equal"] == vec.transmissions + 1  # the initial value and every transmission
    assert got["transmissions"] == vec.transmissions > 100  # 192 and 182


def test_float64_on_the_docs_model_with_two_outputs_per_node(tmp_path):
    """The linear model of docs/models.md, its two outputs sent by one node (a norm of two)."""
    rule = DynamicRule(gamma=Quadratic(1.0), alpha=Linear(1.0), sigma=0.5, c=0.5, eps=1e-3, eta0=0.01)
    _, y = sample_outputs(docs_model(rule), [1.0, 0.0], 100.0, 0.001)
    spec = rule.sensor_spec()
    module(spec, 0.001, tmp_path, n_values=2, node=3)
    vec, path = vectors(spec, 0.001, y, tmp_path, node=3)
    code, got = replay(build(tmp_path), path)
    assert code == 0 and got["samples"] == 100_001 == got["eta_equal"] and got["packets_differ"] == 0
    assert got["transmissions"] == vec.transmissions > 100


RULES = {
    "runge-kutta filter": DynamicRule(
        gamma=Quadratic(5.0), alpha=Quadratic(2.0), sigma=600, c=0.001, eps=10, eta0=10
    ),
    "power (libm pow)": DynamicRule(
        gamma=Power(5.0, 1.5), alpha=Power(3.0, 1.5), sigma=400, c=0.002, b=0.5, eps=10
    ),
    "static": StaticRule(gamma=Quadratic(5.0), eps=10.0),
    "relative": RelativeRule(rho=0.1, eps=0.2),
    "generalized": GeneralizedRule(
        gamma=Quadratic(5.0),
        gamma_check=Linear(2.0),
        alpha_check=Linear(3.0),
        d_prime=0.5,
        sigma=0.5,
        eps=10.0,
    ),
    "periodic": PeriodicRule(period=0.05),
}


@pytest.mark.parametrize("name", list(RULES))
def test_every_kind_a_node_runs_is_written_in_c_bit_for_bit(tmp_path, arm_samples, name):
    spec = RULES[name].sensor_spec()
    module(spec, 0.001, tmp_path)
    vec, path = vectors(spec, 0.001, arm_samples[:20_000, [0]], tmp_path)
    code, got = replay(build(tmp_path), path)
    assert code == 0 and got["samples"] == 20_000 == got["decisions_equal"] == got["eta_equal"], got
    assert got["packets_equal"] == vec.transmissions + 1 and vec.transmissions > 0


def test_no_multiply_add_is_fused_in_gnu_mode_on_this_cpu(tmp_path):
    """gcc's GNU modes fuse a * b + c into one rounding where the CPU has FMA (-march=native):
    without the module's pragma, a three-output node with a Runge-Kutta filter had the Python
    node's eta in only 12,911 of 20,000 samples. With it, in every one."""
    spec = {"kind": "dynamic", "gamma": ["quadratic", 5.0], "alpha": ["quadratic", 2.0], "sigma": 60.0}
    spec |= {"c": 0.01, "b": 0.5, "eps": 0.01, "eta0": 1.0}
    t = np.arange(20_000) * 0.002
    y = np.stack([np.sin(3 * t) + 0.3 * np.cos(17 * t), np.cos(2 * t) * 1.7, 0.5 * np.sin(5 * t)], axis=1)
    module(spec, 0.002, tmp_path, n_values=3)
    _, path = vectors(spec, 0.002, y, tmp_path)
    exe = tmp_path / "gnu"
    src = [str(tmp_path / f) for f in ("etobs_vectors.c", "etobs_node.c", "etobs_sha256.c")]
    subprocess.run(["gcc", "-std=gnu99", "-O2", "-march=native", "-o", str(exe), *src, "-lm"], check=True)
    code, got = replay(exe, path)
    assert code == 0 and got["eta_equal"] == 20_000 and got["packets_differ"] == 0, got


def test_float32_decides_as_float64_except_at_the_threshold_and_eta_drifts_little(tmp_path, arm_samples):
    spec = robot_arm().nodes[0].rule.sensor_spec()
    module(spec, 0.001, tmp_path, profile="float32")
    _, path = vectors(spec, 0.001, arm_samples[:, [0]], tmp_path)
    code, got = replay(build(tmp_path), path, FLOAT32_MARGIN)
    assert code == 0, got
    assert got["worst_margin"] <= FLOAT32_MARGIN and got["max_eta_drift"] <= FLOAT32_DRIFT
    assert got["decisions_equal"] >= 100_001 - 2  # 100,001 of 100,001 seen
    assert got["max_eta_drift"] > 0  # it does compute in single precision


def test_a_decision_near_the_threshold_is_reported_with_its_margin(tmp_path, arm_samples):
    """A float32 disagreement beyond the tolerance fails the runner: with a tolerance of 0 and
    a threshold placed at the samples' own trigger values, the runner must say which margin."""
    rule = RULES["static"]
    spec = rule.sensor_spec()
    y = arm_samples[:2000, [0]]
    # e = |y_k - y_0| hits the static threshold eps exactly at some sample: eps = gamma(|e|) there
    e = np.abs(y[:, 0] - y[0, 0])
    spec = {**spec, "eps": float(5.0 * e[1500] ** 2)}
    module(spec, 0.001, tmp_path, profile="float32")
    _, path = vectors(spec, 0.001, y, tmp_path)
    code, got = replay(build(tmp_path), path, 0.0)
    if got["decision_mismatches"]:
        assert code == 1 and got["worst_margin"] < 1e-6
    else:  # float32 happened to round the same way at that sample: nothing to report
        assert code == 0 and got["worst_margin"] == 0


def test_sha256_and_hmac_are_pythons_on_many_lengths(tmp_path):
    """FIPS 180-4 "abc", RFC 4231 case 1, and messages and keys of every length around the blocks."""
    prog = tmp_path / "sha.c"
    prog.write_text(
        '#include <stdio.h>\n#include <string.h>\n#include "etobs_sha256.h"\n'
        "int main(void) {\n  uint8_t m[300], k[140], d[32]; etobs_sha256 s; int i, n, j;\n"
        "  for (i = 0; i < 300; i++) m[i] = (uint8_t)(i * 7 + 1);\n"
        "  for (i = 0; i < 140; i++) k[i] = (uint8_t)(i * 13 + 5);\n"
        "  for (n = 0; n < 300; n += 1) { etobs_sha256_init(&s); etobs_sha256_update(&s, m, (size_t)n);\n"
        '    etobs_sha256_final(&s, d);\n    for (j = 0; j < 32; j++) printf("%02x", d[j]);\n    printf("\\n"); }\n'
        "  for (n = 0; n < 140; n += 1) { etobs_hmac_sha256(k, (size_t)n, m, 100, d);\n"
        '    for (j = 0; j < 32; j++) printf("%02x", d[j]);\n    printf("\\n"); }\n'
        '  etobs_sha256_init(&s); etobs_sha256_update(&s, (const uint8_t *)"abc", 3); etobs_sha256_final(&s, d);\n'
        '  for (j = 0; j < 32; j++) printf("%02x", d[j]);\n  printf("\\n");\n'
        '  memset(k, 0x0b, 20); etobs_hmac_sha256(k, 20, (const uint8_t *)"Hi There", 8, d);\n'
        '  for (j = 0; j < 32; j++) printf("%02x", d[j]);\n  printf("\\n");\n'
        "  return 0;\n}\n"
    )
    module(RULES["static"].sensor_spec(), 0.01, tmp_path)
    exe = tmp_path / "sha"
    cmd = ["gcc", "-std=c99", "-O2", "-Wall", "-Werror", "-I", str(tmp_path), "-o", str(exe)]
    subprocess.run([*cmd, str(prog), str(tmp_path / "etobs_sha256.c")], check=True)
    lines = subprocess.run([str(exe)], capture_output=True, text=True, check=True).stdout.split()
    m = bytes((i * 7 + 1) % 256 for i in range(300))
    k = bytes((i * 13 + 5) % 256 for i in range(140))
    assert lines[:300] == [hashlib.sha256(m[:n]).hexdigest() for n in range(300)]
    assert lines[300:440] == [hmac.new(k[:n], m[:100], hashlib.sha256).hexdigest() for n in range(140)]
    # the standards' own vectors: FIPS 180-4's "abc", RFC 4231's test case 1
    assert lines[440] == "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
    assert lines[441] == "b0344c61d8db38535ca8afceaf0bf12b881dc200c9833da726e9376c2e32cff7"


def test_the_module_uses_no_heap_and_no_libm_beyond_what_it_states(tmp_path):
    """Undefined symbols of the node's object files: sqrt (and pow for a power K-function), memcpy, memset."""
    for name, rule in (("quadratic", robot_arm().nodes[0].rule), ("power", RULES["power (libm pow)"])):
        folder = tmp_path / name
        mod = module(rule.sensor_spec(), 0.001, folder)
        objs = []
        for src in ("etobs_node.c", "etobs_sha256.c"):
            obj = folder / src.replace(".c", ".o")
            subprocess.run(["gcc", "-std=c99", "-O2", "-c", "-o", str(obj), str(folder / src)], check=True)
            objs.append(str(obj))

        def symbols(*flags: str, objs: list[str] = objs) -> set[str]:
            nm = subprocess.run(["nm", *flags, *objs], capture_output=True, text=True, check=True).stdout
            return {line.split()[-1] for line in nm.splitlines() if line.strip() and ":" not in line}

        undefined = symbols("-u") - symbols("--defined-only")
        stated = {"sqrt", "pow"} if name == "power" else {"sqrt"}
        assert undefined - {"memcpy", "memset"} == stated, undefined
        assert "libm: " + ", ".join(sorted(stated, reverse=True)) in mod.files["etobs_node.h"]


def test_the_example_main_loop_builds_and_runs(tmp_path):
    module(robot_arm().nodes[0].rule.sensor_spec(), 0.002, tmp_path)
    exe = build(tmp_path, "main.c", "main")
    out = subprocess.run([str(exe)], capture_output=True, text=True, timeout=60, check=True).stdout
    sent = int(out.split(", ")[1].split()[0])
    assert out.startswith("main: 1000 samples,") and sent > 0 and f"{sent + 1} packets" in out


# ---- bad input --------------------------------------------------------------------------


def test_what_the_generator_cannot_write_is_one_line_naming_it():
    custom = DynamicRule(gamma=Custom(lambda s: 5 * s * s), alpha=Linear(2.0), eps=10.0)
    with pytest.raises(
        InputError, match=r"a sensor node runs the K-functions of etobs' kinds .*; `gamma` is Custom"
    ):
        custom.sensor_spec()
    with pytest.raises(InputError, match=r"etobs codegen c: rule spec: `kind` must be one of .*; got 'mine'"):
        generate_node({"kind": "mine"}, 0.01, node=0, n_values=1)
    with pytest.raises(InputError, match=r"`profile` must be one of float64, float32; got 'float16'"):
        generate_node(RULES["static"].sensor_spec(), 0.01, node=0, n_values=1, profile="float16")
    with pytest.raises(InputError, match=r"`node` must be an integer in 0..65535; got 65536"):
        generate_node(RULES["static"].sensor_spec(), 0.01, node=65536, n_values=1)
    with pytest.raises(InputError, match=r"`n_values` must be an integer in 1..64; got 0"):
        generate_node(RULES["static"].sensor_spec(), 0.01, node=0, n_values=0)
    huge = {"kind": "periodic", "period": 1e17}  # 10^19 samples a period: beyond a 64-bit count
    with pytest.raises(InputError, match=r"a periodic rule of 10000000000000000000 samples a period"):
        generate_node(huge, 0.01, node=0, n_values=1)
    assert generate_node({"kind": "periodic", "period": 1e16}, 0.01, node=0, n_values=1).kind == "periodic"


FACTORY = """
from etobs.examples.robot_arm import robot_arm
from etobs.model import Custom, DynamicRule, Linear, Sampled
from etobs.model.rules import StatelessRule
import dataclasses
import etobs

@etobs.factory
def custom():
    pb = robot_arm()
    rule = DynamicRule(gamma=Custom(lambda s: 5 * s * s), alpha=Linear(2.0), eps=10.0)
    return dataclasses.replace(pb, nodes=(dataclasses.replace(pb.nodes[0], rule=rule), pb.nodes[1]))

class Mine(StatelessRule):
    def trigger(self, t, e, s, y=None):
        return e[:, 0] - 1.0


@etobs.factory
def own():
    pb = robot_arm()
    return dataclasses.replace(pb, nodes=(pb.nodes[0], dataclasses.replace(pb.nodes[1], rule=Mine())))


@etobs.factory
def phased():
    pb = robot_arm()
    nodes = tuple(dataclasses.replace(nd, rule=Sampled(nd.rule, 0.002, phase=0.001 * i)) for i, nd in enumerate(pb.nodes))
    return dataclasses.replace(pb, nodes=nodes)


@etobs.factory
def sampled():
    pb = robot_arm()
    nodes = tuple(dataclasses.replace(nd, rule=Sampled(nd.rule, 0.005)) for nd in pb.nodes)
    return dataclasses.replace(pb, nodes=nodes)
"""


@pytest.mark.parametrize(
    ("factory", "node", "message"),
    [
        ("custom", 0, r"a sensor node runs the K-functions of etobs' kinds .*`gamma` is Custom"),
        (
            "sampled",
            0,
            r"node 0's rule is sampled at period 0.005 s, phase 0.0 s in the model, but a node "
            r"samples at k \* `runtime.period` = k \* 0.002 s",
        ),
        ("phased", 1, r"node 1's rule is sampled at period 0.002 s, phase 0.001 s in the model"),
        ("custom", 2, r"--node must be in 0..1; got 2"),
        (
            "own",
            1,
            r"a sensor node runs the rules of etobs' kinds \(dynamic, .*\); got Mine, a rule of your own",
        ),
    ],
)
def test_codegen_cli_mistakes_are_one_line(tmp_path, capsys, factory, node, message):
    (tmp_path / "models.py").write_text(FACTORY)
    spec = tmp_path / "spec.toml"
    spec.write_text(
        f'name = "t"\n[system]\nfactory = "models.py:{factory}"\n[runtime]\nperiod = 0.002\nduration = 1.0\n'
    )
    with pytest.raises(SystemExit) as e:
        main(["codegen", "c", str(spec), "--node", str(node), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert e.value.code == 2 and len(lines) == 1 and lines[0].startswith("etobs: error:"), err
    assert re.search(message, lines[0]), lines[0]
    assert not (tmp_path / "out").exists()


def test_codegen_cli_writes_a_module_and_vectors_that_agree(tmp_path, capsys):
    out = tmp_path / "node1"
    assert main(["codegen", "c", "robot_arm", "--node", "1", "--out", str(out)]) == 0
    assert (
        main(
            [
                "codegen",
                "vectors",
                "robot_arm",
                "--node",
                "1",
                "--out",
                str(tmp_path / "v.txt"),
                "--duration",
                "3",
            ]
        )
        == 0
    )
    said = capsys.readouterr().out
    assert "wrote 9 files" in said and "node 1, the sampled dynamic rule at T = 0.002 s" in said
    assert "1501 samples" in said
    code, got = replay(build(out), tmp_path / "v.txt")
    assert code == 0 and got["samples"] == 1501 == got["eta_equal"] and got["packets_differ"] == 0
    assert sorted(p.name for p in out.iterdir()) == sorted(
        ["LICENSE", "README.md", "etobs_host.c", "etobs_node.c", "etobs_node.h", "etobs_sha256.c",
         "etobs_sha256.h", "etobs_vectors.c", "main.c", "run"]
    )  # fmt: skip
    assert Path(HERE).exists()
