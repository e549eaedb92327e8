"""docs/specs.md lists every key of every spec format, and only keys the parsers accept.

The keys each parser accepts are not written down a second time here: they are recorded
from the parsers themselves, by watching every call to :func:`etobs._spec.keys` (the
required and the optional keys of each table) while the page's full examples are parsed.
Each format's table on the page must then hold exactly those keys, with "required" where
the parser requires them. Every example on the page is parsed (the check examples through
``etobs check``, as a user runs them).
"""

import re
import sys
from collections import defaultdict
from contextlib import contextmanager
from pathlib import Path

import pytest

# the parsers, imported before their keys are watched
import etobs._spec
import etobs.cli.check
import etobs.experiments.compare_spec
import etobs.experiments.spec
import etobs.runtime.deployment
import etobs.tuning.spec
from etobs._spec import SpecError

PAGE = Path(__file__).resolve().parents[1] / "docs" / "specs.md"
FORMATS = ("sweep", "compare", "check", "tune", "deploy")
#: Tables of factory arguments: any argument of the factory (rows ``TABLE.*`` on the page),
#: checked against its signature, not by :func:`etobs._spec.keys`.
ARGUMENT_TABLES = {"system.fixed", "system.params", "rows[]", "grid", "scenarios[]"}
#: Keys read without :func:`etobs._spec.keys`, because their table also holds factory
#: arguments; test_keys_read_by_hand_are_required checks them.
BY_HAND = {"sweep": {"scenarios[].name"}}


def page_tables(text):
    """{format: {key: required column}} from the tables after ``<!-- keys: FORMAT ... -->``."""
    out = {f: {} for f in FORMATS}
    for match in re.finditer(r"<!-- keys: ([a-z ]+) -->\n((?:\|.*\n)+)", text):
        rows = match[2].splitlines()
        header = [c.strip() for c in rows[0].strip("|").split("|")]
        assert header[:4] == ["key", "type", "default", "required"], header
        for row in rows[2:]:
            cells = [c.strip() for c in re.split(r"(?<!\\)\|", row.strip().strip("|"))]
            key = re.fullmatch(r"`([^`]+)`", cells[0])
            assert key, f"the first column must be a key in backquotes: {row}"
            for fmt in match[1].split():
                assert key[1] not in out[fmt], f"{key[1]} listed twice for {fmt}"
                out[fmt][key[1]] = cells[3]
    return out


def page_examples(text):
    """{(format, "minimal" | "full"): TOML text} of the blocks after ``<!-- example: ... -->``."""
    found = re.findall(r"<!-- example: ([a-z]+) (minimal|full) -->\n```toml\n(.*?)```", text, re.S)
    return {(fmt, kind): body for fmt, kind, body in found}


TEXT = PAGE.read_text()
TABLES = page_tables(TEXT)
EXAMPLES = page_examples(TEXT)


@contextmanager
def recording():
    """Record ``(where, required, optional)`` of every :func:`etobs._spec.keys` call.

    The parsers import it as ``_keys``; each module's name is pointed at a recorder.
    """
    calls = []
    real = etobs._spec.keys

    def record(where, table, required, optional):
        calls.append((where, set(required), set(optional)))
        return real(where, table, required, optional)

    modules = [m for m in list(sys.modules.values()) if getattr(m, "_keys", None) is real]
    assert modules, "no parser imports etobs._spec.keys as _keys"
    for m in modules:
        m._keys = record
    try:
        yield calls
    finally:
        for m in modules:
            m._keys = real


def parse(fmt, text, tmp_path, capsys):
    """Parse (and check, as the commands do before any run) the spec ``text`` of format ``fmt``."""
    import tomllib

    from etobs.cli.main import main
    from etobs.experiments.compare_spec import parse_compare_spec
    from etobs.experiments.spec import parse_spec
    from etobs.runtime.deployment import parse_deployment

    if fmt == "check":
        pytest.importorskip("cvxpy")
        spec = tmp_path / "check.toml"
        spec.write_text(text)
        code = main(["check", str(spec)])
        out = capsys.readouterr()
        assert code == 0, out.out + out.err  # the examples certify: every condition holds
        return
    raw = tomllib.loads(text)
    if fmt == "tune":  # parsed, then its observers' gains and E computed, as before the first trial
        pytest.importorskip("cvxpy")
        from etobs.tuning.evaluate import Evaluator
        from etobs.tuning.spec import parse_tune_spec

        Evaluator(parse_tune_spec(raw), None, {})
        return
    if fmt == "deploy":
        parse_deployment(raw, tmp_path)
        return
    spec = (parse_spec if fmt == "sweep" else parse_compare_spec)(raw)
    spec.check()  # the factory's arguments (a comparison builds every entry)


def accepted(calls):
    """{key path: whether it was required in every call} of the recorded calls.

    A tuning's ``parameters.sigma.low`` is listed as ``parameters.<name>.low``, and an
    ``[[observers]]`` entry's keys (but its name) as the ``observer.*`` they are.
    """
    required = defaultdict(list)
    for where, req, opt in calls:
        where = re.sub(r"^parameters\.[^.]+$", "parameters.<name>", where)
        if re.fullmatch(r"observers\[\d+\]", where):
            for k in req | opt:
                required["observers[].name" if k == "name" else f"observer.{k}"].append(k in req)
            continue
        prefix = "" if where == "spec" else re.sub(r"\[\d+\]", "[]", where) + "."
        for k in req | opt:
            required[prefix + k].append(k in req)
    return required


@pytest.mark.parametrize(("fmt", "kind"), [(f, k) for f in FORMATS for k in ("minimal", "full")])
def test_every_example_on_the_page_is_a_valid_spec(fmt, kind, tmp_path, capsys):
    parse(fmt, EXAMPLES[(fmt, kind)], tmp_path, capsys)


@pytest.mark.parametrize("fmt", FORMATS)
def test_the_page_lists_exactly_the_keys_the_parser_accepts(fmt, tmp_path, capsys):
    with recording() as calls:
        parse(fmt, EXAMPLES[(fmt, "full")], tmp_path, capsys)
    parser = accepted(calls)
    page = TABLES[fmt]
    free = {k for k in page if k.endswith(".*")}
    assert {k[:-2] for k in free} <= ARGUMENT_TABLES, free
    listed = set(page) - free - BY_HAND.get(fmt, set())
    assert sorted(set(parser) - listed) == [], f"accepted by the {fmt} parser but not on the page"
    assert sorted(listed - set(parser)) == [], f"on the page but refused by the {fmt} parser"
    for key, required in parser.items():
        if page[key] == "yes":
            assert all(required), f"{key}: the page says required, the parser does not require it"
        elif page[key].startswith("no"):
            assert not any(required), f"{key}: the page says not required, the parser requires it"


def test_keys_read_by_hand_are_required():
    import tomllib

    from etobs.experiments.spec import parse_spec

    raw = tomllib.loads(EXAMPLES[("sweep", "full")])
    del raw["scenarios"][1]["name"]
    with pytest.raises(SpecError, match=r"missing key `scenarios\[1\].name`"):
        parse_spec(raw)
    assert TABLES["sweep"]["scenarios[].name"] == "yes"


def test_every_format_has_a_table_and_two_examples():
    assert all(TABLES[f] for f in FORMATS)
    assert set(EXAMPLES) == {(f, k) for f in FORMATS for k in ("minimal", "full")}


def test_a_page_without_a_key_or_with_a_bogus_one_fails(tmp_path, capsys):
    # the check above can fail: a row removed from the page, or one added, is seen
    with recording() as calls:
        parse("deploy", EXAMPLES[("deploy", "full")], tmp_path, capsys)
    parser = set(accepted(calls))
    page = set(TABLES["deploy"]) - {"system.params.*"}
    assert page == parser
    assert page - {"runtime.topic"} != parser
    assert page | {"runtime.colour"} != parser
