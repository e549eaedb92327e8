"""Every paper label the project cites is the paper's (issue 15, item 7).

The spec is the paper's LaTeX source beside the repository
(``../shared/paper/decentralized-event-triggered-estimation.tex``). :func:`number_paper`
numbers it as LaTeX prints it with its class (elsarticle): sections and subsections,
equations numbered through the paper ((A.n) in the appendix; ``align``-like rows one
number each; ``split``/``aligned``/``array`` inside one equation none; ``\\nonumber``,
``\\notag``, starred forms none; ``subequations`` (Na), (Nb)), one counter per
``\\newtheorem`` unless it shares one, figures and tables by their captions.

Then every citation in src/, docs/, tests/, benchmarks/, examples/ and README.md ("eq.
(15)", "eqs. (16)-(17)", "(16)--(22)", "Assumption 2", "Theorems 1-4", "Remark 3",
"section 7.2", "§7.3", "Table 1", ...) is checked: the number must exist in the paper,
and where its line names a concept of :data:`CONCEPTS` (the ISS assumption, the minimum
inter-event time, the input trigger, ...) each cited number must be one of those
concepts' (so "Theorem 3's minimum inter-event time" fails: that is Theorem 4).
docs/notation.md's numbering table is checked against the LaTeX too.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAPER = ROOT.parent / "shared" / "paper" / "decentralized-event-triggered-estimation.tex"
#: Where citations are looked for (this file is left out: its examples cite wrong labels).
SCANNED = ("src", "docs", "tests", "benchmarks", "examples", "README.md")
SUFFIXES = {".py", ".md", ".toml", ".txt", ".cfg", ".rst"}


# -- numbering the LaTeX ----------------------------------------------------------------------


@dataclass(frozen=True)
class Item:
    """One numbered thing of the paper: ``kind`` is ``equation``, ``section`` or a title."""

    kind: str
    number: str
    label: str | None
    line: int


EQ_ONE = {"equation", "multline"}  # one number per environment
EQ_ROWS = {"align", "gather", "flalign", "alignat", "eqnarray"}  # one number per row
FLOATS = {"figure": "Figure", "table": "Table"}
TOKEN = re.compile(r"\\(section|subsection|subsubsection|appendix|label|caption|begin|end)\b(\*?)")
NO_NUMBER = re.compile(r"\\(?:nonumber|notag)\b")


def _strip_comments(tex: str) -> str:
    return "\n".join(re.sub(r"(?<!\\)%.*", "", line) for line in tex.splitlines())


def _group(text: str, pos: int) -> tuple[str, int]:
    """The brace group opening at ``text[pos]`` and the index after it."""
    depth, i = 0, pos
    while True:
        c = text[i]
        if c == "\\":
            i += 2
            continue
        depth += {"{": 1, "}": -1}.get(c, 0)
        i += 1
        if depth == 0:
            return text[pos + 1 : i - 1], i


def _argument(text: str, pos: int) -> tuple[str | None, int]:
    """The next ``{...}`` argument after ``pos`` (skipping spaces and one ``[...]``)."""
    pos = re.compile(r"\s*(?:\[[^\]]*\]\s*)?").match(text, pos).end()
    if pos >= len(text) or text[pos] != "{":
        return None, pos
    return _group(text, pos)


def _theorem_kinds(preamble: str) -> dict[str, tuple[str, str, str | None]]:
    """``\\newtheorem{env}[shared]{Title}[within]`` -> env: (Title, counter, within)."""
    kinds: dict[str, tuple[str, str, str | None]] = {}
    for m in re.finditer(r"\\newtheorem\s*\{(\w+)\}\s*(?:\[(\w+)\])?", preamble):
        title, end = _argument(preamble, m.end())
        within = re.match(r"\s*\[(\w+)\]", preamble[end:])
        word = re.findall(r"[A-Za-z]+", re.sub(r"\\[A-Za-z]+", " ", title))[-1]
        counter = kinds[m.group(2)][1] if m.group(2) else m.group(1)
        kinds[m.group(1)] = (word, counter, within.group(1) if within else None)
    return kinds


def _rows(body: str) -> list[str]:
    """An align-like body split at its own ``\\\\`` (not those of nested groups)."""
    out, depth, start, i = [], 0, 0, 0
    while i < len(body):
        if body.startswith("\\begin", i) or body[i] == "{":
            depth += 1
        elif body.startswith("\\end", i) or body[i] == "}":
            depth -= 1
        elif body.startswith("\\\\", i) and depth == 0:
            out.append(body[start:i])
            start = i = i + 2
            continue
        if body[i] == "\\":
            i += 2
            continue
        i += 1
    out.append(body[start:])
    if len(out) > 1 and not out[-1].strip():
        out.pop()  # a final \\ opens no row
    return out


def number_paper(tex: str) -> list[Item]:
    """Every numbered item of the paper, with its label when it has one."""
    tex = _strip_comments(tex)
    start = tex.index("\\begin{document}")
    kinds = _theorem_kinds(tex[:start])
    items: list[Item] = []
    counters: dict[str, int] = {}
    floats = dict.fromkeys(FLOATS, 0)
    sec = [0, 0, 0]
    appendix = False
    eq = 0
    sub: list | None = None  # [parent number, letters used] inside subequations
    # label targets: one frame per open environment, (kind, number, position) or None
    stack: list[list] = [["document", None]]

    def line(pos: int) -> int:
        return tex.count("\n", 0, pos) + 1

    def sec_number(level: int) -> str:
        head = chr(ord("A") + sec[0] - 1) if appendix else str(sec[0])
        return ".".join([head] + [str(n) for n in sec[1 : level + 1]])

    def next_equation() -> str:
        nonlocal eq
        if sub is not None:
            sub[1] += 1
            return f"{sub[0]}{chr(ord('a') + sub[1] - 1)}"
        eq += 1
        return f"{chr(ord('A') + sec[0] - 1)}.{eq}" if appendix else str(eq)

    pos = start
    while m := TOKEN.search(tex, pos):
        cmd, star = m.groups()
        pos = m.end()
        if cmd in ("section", "subsection", "subsubsection"):
            _, pos = _argument(tex, pos)
            if star:
                continue
            level = ("section", "subsection", "subsubsection").index(cmd)
            sec[level] += 1
            sec[level + 1 :] = [0] * (2 - level)
            if appendix and level == 0:
                eq = 0  # elsarticle: (A.1), (B.1), ... in the appendices
            stack[0][1] = ("section", sec_number(level), m.start())
            items.append(Item("section", sec_number(level), None, line(m.start())))
        elif cmd == "appendix":
            appendix, sec, eq = True, [0, 0, 0], 0
        elif cmd == "label":
            name, pos = _argument(tex, pos)
            target = next(frame[1] for frame in reversed(stack) if frame[1] is not None)
            items.append(Item(target[0], target[1], name, line(target[2])))
        elif cmd == "caption":
            frame = next(f for f in reversed(stack) if f[0] in FLOATS)
            floats[frame[0]] += 1
            frame[1] = (FLOATS[frame[0]], str(floats[frame[0]]), m.start())
            items.append(Item(FLOATS[frame[0]], str(floats[frame[0]]), None, line(m.start())))
        elif cmd == "begin":
            full, pos = _argument(tex, pos)
            env, starred = full.rstrip("*"), full.endswith("*")
            if env in EQ_ONE | EQ_ROWS:
                end = tex.index(f"\\end{{{full}}}", pos)
                offset = pos
                for row in _rows(tex[pos:end]) if env in EQ_ROWS else [tex[pos:end]]:
                    tag = re.search(r"\\tag\s*\{([^}]*)\}", row)
                    number = tag.group(1) if tag else None
                    if not (starred or NO_NUMBER.search(row) or tag):
                        number = next_equation()
                    if number is not None:
                        items.append(Item("equation", number, None, line(offset)))
                        for name in re.findall(r"\\label\s*\{([^}]*)\}", row):
                            items.append(Item("equation", number, name, line(offset)))
                    offset += len(row) + 2
                pos = end + len(f"\\end{{{full}}}")
            elif env == "subequations":
                eq += 1
                sub = [str(eq), 0]
                stack.append([env, ("equation", str(eq), m.start())])
            elif env in kinds and not starred:
                title, counter, within = kinds[env]
                counters[counter] = counters.get(counter, 0) + 1
                number = str(counters[counter])
                if within:
                    number = f"{sec_number(0)}.{number}"
                stack.append([env, (title, number, m.start())])
                items.append(Item(title, number, None, line(m.start())))
            else:
                stack.append([env, None])
        elif cmd == "end":
            full, pos = _argument(tex, pos)
            if full == "document":
                break
            frame = stack.pop()
            assert frame[0] == full.rstrip("*"), f"\\end{{{full}}} closes {frame[0]} (line {line(m.start())})"
            if full == "subequations":
                sub = None
    return items


#: The paper's numbering as :func:`number_paper` reads it, kept in the repository so that
#: every citation is checked on a clone that has no ../shared/paper (a clean CI clone);
#: where the LaTeX is beside the repository, the fixture checks the copy against it.
NUMBERING = Path(__file__).with_name("paper_numbering.json")


def write_numbering() -> None:
    """Write :data:`NUMBERING` from the LaTeX (run when the paper changes)."""
    items = number_paper(PAPER.read_text(encoding="utf-8"))
    NUMBERING.write_text(json.dumps([vars(it) for it in items], indent=0) + "\n", encoding="utf-8")


@pytest.fixture(scope="module")
def paper() -> list[Item]:
    stored = [Item(**it) for it in json.loads(NUMBERING.read_text(encoding="utf-8"))]
    if PAPER.is_file():
        assert number_paper(PAPER.read_text(encoding="utf-8")) == stored, (
            f"{NUMBERING.name} is not the numbering of {PAPER}: rewrite it with "
            "python -c 'from tests.test_paper_labels import write_numbering; write_numbering()'"
        )
    return stored


def _labels(items: list[Item]) -> dict[str, Item]:
    return {it.label: it for it in items if it.label is not None}


def _numbers(items: list[Item]) -> dict[str, set[str]]:
    out: dict[str, set[str]] = {}
    for it in items:
        out.setdefault(it.kind, set()).add(it.number)
    return out


# -- what the code cites ------------------------------------------------------------------------

KIND_WORDS = {
    "equation": r"\b(?:eqs?\.?|equations?)",
    "section": r"(?:\bsections?\b|\bsecs?\.|§§?)",
    "Theorem": r"\btheorems?\b",
    "Assumption": r"\bassumptions?\b",
    "Remark": r"\bremarks?\b",
    "Lemma": r"\blemmas?\b",
    "Proposition": r"\bpropositions?\b",
    "Figure": r"\b(?:Fig(?:ure)?s?\b\.?)",
    "Table": r"\bTables?\b",
}
_NUM = r"(?:\d+(?:\.\d+)*[a-z]?|[A-H]\.\d+)"
_SEP = r"\s*(?:,|and|or|to|--|[-–—])\s*"
CITE = re.compile(
    "|".join(
        rf"(?P<{kind}>{word})\s*~?(?P<{kind}_n>\(?{_NUM}\)?(?:{_SEP}\(?{_NUM}\)?)*)"
        for kind, word in KIND_WORDS.items()
    )
    + rf"|(?<![\w)\]])(?P<bare_n>\({_NUM}\)\s*(?:--|[-–—])\s*\({_NUM}\))",  # (16)–(22)
    re.IGNORECASE,
)
#: Case matters for these: "table" and "figure" are common words.
CASED = {"Figure", "Table"}


def _expand(numbers: str) -> list[str]:
    """'(16)--(22)' -> 16..22; '7.1-7.3' -> 7.1, 7.2, 7.3; '(3), (7)' -> 3, 7."""
    out: list[str] = []
    parts = re.split(rf"({_SEP})", numbers)
    previous_range = False
    for part in parts:
        if re.fullmatch(_SEP, part):
            previous_range = part.strip() in ("--", "-", "–", "—", "to")
            continue
        n = part.strip().strip("()")
        if previous_range and out:
            a, b = out[-1].rsplit(".", 1) if "." in out[-1] else ("", out[-1])
            b_end = n.rsplit(".", 1)[-1]
            if b.isdigit() and b_end.isdigit() and int(b) < int(b_end) <= int(b) + 40:
                prefix = f"{a}." if a else ""
                out.extend(f"{prefix}{k}" for k in range(int(b) + 1, int(b_end) + 1))
                continue
        out.append(n)
    return out


@dataclass(frozen=True)
class Citation:
    path: str
    line: int
    kind: str
    numbers: tuple[str, ...]
    text: str  # the line(s) the citation is on, and the line before
    start: int  # where the citation starts in ``text``
    end: int
    offset: int  # where ``text`` starts in the file


def citations_in(text: str, path: str = "<text>", wrapped: bool = False) -> list[Citation]:
    """The paper citations in a file's text; ``wrapped`` for prose (Markdown)."""
    out = []
    for m in CITE.finditer(text):
        if m.group("bare_n"):
            kind, numbers = "equation", m.group("bare_n")
        else:
            kind = next(k for k in KIND_WORDS if m.group(k) is not None)
            numbers = m.group(f"{kind}_n")
            if kind in CASED and not m.group(kind)[0].isupper():
                continue
        if kind != "equation" and numbers.startswith("("):
            continue  # "Theorem (ii)" is no number; "Remark (1)" is not how we cite
        first = text.rfind("\n", 0, m.start()) + 1
        if wrapped:  # a paragraph's line before is part of the sentence (not so in code or tables)
            before = text.rfind("\n", 0, max(0, first - 1)) + 1
            line_end = text.find("\n", first)
            this = text[first : len(text) if line_end < 0 else line_end]
            if not {text[before:first].strip()[:1], this.strip()[:1]} & {"", "|", "#"}:
                first = before
        last = text.find("\n", m.end())
        last = len(text) if last < 0 else last
        out.append(
            Citation(
                path,
                text.count("\n", 0, m.start()) + 1,
                kind,
                tuple(_expand(numbers.rstrip(".,;"))),
                text[first:last],
                m.start() - first,
                m.end() - first,
                first,
            )
        )
    return out


def scanned_files() -> list[Path]:
    files = []
    for name in SCANNED:
        path = ROOT / name
        if path.is_file():
            files.append(path)
        else:
            files.extend(p for p in sorted(path.rglob("*")) if p.suffix in SUFFIXES and p.is_file())
    # the site's build outputs (make docs) copy the pages: their citations are the pages'
    generated = {".venv", "_build", "generated", "gallery_out"}
    return [p for p in files if p.resolve() != Path(__file__).resolve() and not generated & set(p.parts)]


def all_citations() -> list[Citation]:
    out = []
    for path in scanned_files():
        text = path.read_text(encoding="utf-8", errors="replace")
        out.extend(citations_in(text, str(path.relative_to(ROOT)), wrapped=path.suffix == ".md"))
    return out


# -- what the citations mean ----------------------------------------------------------------------


@dataclass(frozen=True)
class Concept:
    """Words that, on a citing line, say which paper item is meant; ``labels`` are its LaTeX labels."""

    name: str
    labels: tuple[str, ...]
    words: str


#: A citation of a kind (equation, section, Theorem, ...) on a line where some of these
#: concepts' words occur must cite only numbers of those concepts (of that kind); a concept
#: with no label of the citation's kind does not constrain it. Words are matched
#: case-insensitively. Keep them specific: a word common to two concepts lets a wrong
#: citation of one pass as the other.
CONCEPTS = (
    Concept(
        "the observer knows u",
        ("assumption 1",),
        r"access to (the )?(plant )?input|observer knows (the )?(input|`?u\b)",
    ),
    Concept(
        "the observer's ISS property",
        ("ISSassumption",),
        r"\bISS\b(?! gain `?gamma_u)|iss_gains|input-to-state|dissipation|\bgamma_i\b|\btheta\b|quadratic gains",
    ),
    Concept(
        "the dissipation inequality",
        ("eq:ISSassumptionDerivative",),
        r"dissipation|ISS (inequality|property)|Assumption 2\b|quadratic ``?theta|\btheta\(",
    ),
    Concept(
        "the sandwich bound of V",
        ("eq:ISSassumptionSandwichBound",),
        r"sandwich|alpha_lower|underline\{?alpha",
    ),
    Concept(
        "the held output",
        ("eq:bar_yi", "eq:yplus", "eq:yplusBis"),
        r"ybar_?i?'? = 0|ybar_?i?\+|zero-order hold",
    ),
    Concept("the observer on held outputs", ("eq:observerAlly", "eq:observerNew"), r"f_o\(|xhat = psi"),
    Concept("the plant", ("eq:system",), r"f_p\(|\bx' = "),
    Concept(
        "the network-induced error's dynamics",
        ("eq:samplingErrorContinuous", "eq:samplingErrorDiscrete", "eq:samplingErrorDiscreteBis"),
        r"e-dynamics|``e``-dynamics|e_i' =",
    ),
    Concept(
        "the eta filter",
        ("eq: etaEquation", "TriggeringRuleAndHybridModel"),
        r"\beta_?i?' =|\beta_?i?\+|eta <- b|eta_reset|dynamic_flow|filter ``?eta|eta-dynamics",
    ),
    Concept(
        "the triggering rule",
        ("eq:triggeringRule", "TriggeringRuleAndHybridModel", "eq:FlowSet_i", "eq:JumpSet_i"),
        r"gamma_?i?\(\|e_?i?\|\) >=|>= sigma_?i? alpha|sigma = 0|absolute[- ]threshold|triggering rule|with equality",
    ),
    Concept("the dynamic rule", ("eq: etaEquation", "eq:triggeringRule"), r"dynamic (triggering )?rule"),
    Concept(
        "the hybrid model",
        tuple(
            f"eq:{n}"
            for n in (
                "HybridSystem",
                "FlowSet",
                "FlowSet_i",
                "JumpSet",
                "JumpSet_i",
                "jumpMap",
                "jumpMap_i_Esplicit",
            )
        ),
        r"hybrid (model|system)\b|flow set|jump set|jump map|\be_k?\+ = 0",
    ),
    Concept(
        "the Lyapunov function U", ("eq:LyapunovDefinitionU", "theoremLyapunov"), r"\bU = V\b|U = V'? \+"
    ),
    Concept(
        "U at jumps", ("eq:stabilityTheoremJump", "theoremLyapunov"), r"U\+ <=|never increases|\bU\[jumps"
    ),
    Concept(
        "Theorem 1's conditions",
        (
            "theoremLyapunov",
            "theoremLyapunovSolutionLinear",
            "eq:LyapunovDefinitionU",
            "LyapunovPropertiesSubsection",
        ),
        r"\bd_?i?\*|d_i\^\*|\bdelta_i\b|sigma_?i?\*? ?c_?i?\*? <|sigma\*c",
    ),
    Concept(
        "nu",
        ("theoremLyapunov", "eq:stabilityTheoremFlow", "LyapunovPropertiesSubsection"),
        r"(?<![.\w])nu\b",
    ),
    Concept("practical stability", ("TheoremLyapunovSolution",), r"practical stability|\bbeta_U\b"),
    Concept(
        "the linear decay rate",
        ("theoremLyapunovSolutionLinear", "decayRateRemark"),
        r"\ba_U\b|\bmu\b|decay rate",
    ),
    Concept(
        "the observer copy", ("RemarkWhyOnlyPractical",), r"observer[- ]copy|copy of the observer|innovation"
    ),
    Concept("freedom in the ISS gains", ("remarkFreedomISSgains",), r"ell_i s\^2 different|any quadratic"),
    Concept(
        "completeness of maximal solutions",
        (
            "TheoremCompletenessOfMaximalSolutions",
            "forwardCompleteAssumption",
            "Completeness of maximal solutions",
        ),
        r"completeness|forward[- ]complete",
    ),
    Concept(
        "the minimum inter-event time",
        ("theoremIndividualInterEventTime", "IET"),
        r"inter-event|\bMIET\b|\btau_i\b|dwell[- ]time",
    ),
    Concept(
        "the rate bound E",
        ("eq:SM set", "theoremIndividualInterEventTime", "IET"),
        r"\|dh_?i?/dx f_p\||\bbound `?`?E\b|derivative bound|the bound ``E``",
    ),
    Concept(
        "transmissions stop",
        ("Lemma_stopTransmissions", "stopTransmissionSubsection", "eq:stopTransmission_i"),
        r"transmissions? (to )?stops?|stops? transmitting|at most one more|stays within",
    ),
    Concept("the change of supply rates", ("LemmaMultipleChangeOfSupplyRate",), r"supply rate"),
    Concept(
        "the extensions",
        ("discussionSection", "generalTriggeringCondition", "MeasurementNoise", "TriggeredInput"),
        r"extensions?\b|\bextends\b",
    ),
    Concept(
        "the generalized rule",
        (
            "generalTriggeringCondition",
            "eq:etaDotRemarkGeneralTriggering",
            "eq:triggeringRuleRemarkGeneralTriggering",
        ),
        r"generali[sz]ed|alpha_check|gamma_check|d_prime|\bd'",
    ),
    Concept(
        "the generalized filter", ("eq:etaDotRemarkGeneralTriggering",), r"-alpha_check\(eta\) \+ gamma_check"
    ),
    Concept(
        "measurement noise",
        ("MeasurementNoise",),
        r"noise\b|gamma_?i?\(2 ?m",
    ),
    Concept(
        "the noisy output", ("eq:systemWithMeasurementNoise", "MeasurementNoise"), r"ytilde = h|h\(x\) \+ m"
    ),
    Concept(
        "input triggering",
        ("TriggeredInput", "ISSassumptionInputTriggered"),
        r"input nodes?\b|InputNode|triggered input|triggering the input|triggers? the input|input trigger|bound on ``?u'",
    ),
    Concept(
        "the observer on the held input",
        ("eq:observerNewInputTriggered", "TriggeredInput"),
        r"held input|observer on ``?ubar|ubar = |e_u = ubar",
    ),
    Concept("Assumption 4", ("ISSassumptionInputTriggered",), r"ISS gain `?gamma_u"),
    Concept(
        "the input's eta filter",
        ("eq:etaEquationTriggeredInput", "TriggeredInput"),
        r"\beta_u\b|\bc_u\b|\bb_u\b|alpha_u",
    ),
    Concept(
        "the input's trigger",
        ("eq:inputTriggeringRule", "TriggeredInput"),
        r"gamma_u\(\|e_u\|\) >=|\bsigma_u\b|\beps_u\b|with equality",
    ),
    Concept(
        "the robot-arm case study",
        (
            "Example",
            "tab:SimulationData",
            "fig:StateAndEstimate",
            "fig:NormEstimationError",
            "fig:InterTransmissionsTime",
        ),
        r"robot[- ]arm|case study|flexible[- ]joint|printed (gain|L\b)|paper's (first )?simulation|\bLMIs?\b"
        r"|Luenberger|\bc_v\b|P`?, `?L`?, `?Q|split constants|measured minimum|three figures|G_1, G_2|Table 1|paper's metrics|\bmeasured\b",
    ),
    Concept(
        "the block diagram", ("Fig:blockDiagramDistributed", "Fig:sensorNode"), r"block diagram|sensor node's"
    ),
    Concept("the states and estimates figure", ("fig:StateAndEstimate",), r"plot_states|x_k`? and `?xhat_k"),
    Concept("the error figure", ("fig:NormEstimationError",), r"plot_error|\|x - xhat\|`? against"),
    Concept(
        "the inter-event figure",
        ("fig:InterTransmissionsTime",),
        r"plot_inter_event_times|inter-transmission times",
    ),
    Concept(
        "what certify covers",
        ("theoremLyapunov", "theoremLyapunovSolutionLinear", "theoremIndividualInterEventTime"),
        r"\bcertify\(",
    ),
)


def _allowed(concept: Concept, labels: dict[str, Item], kind: str) -> set[str]:
    return {labels[name].number for name in concept.labels if labels[name].kind == kind}


#: Concept words farther than this (characters) from a citation do not speak of it.
NEAR = 40


def _gap(a: tuple[int, int], b: tuple[int, int]) -> int:
    return max(0, max(a[0], b[0]) - min(a[1], b[1]))


def _show(c: Citation) -> str:
    return c.text[c.text.rfind("\n", 0, c.start) + 1 :].strip()


def wrong_citations(cites: list[Citation], items: list[Item]) -> list[str]:
    """A message per citation whose number is not in the paper or not the concept named beside it.

    A concept's words on a line speak of the citation (of a kind the concept has labels
    of) nearest to them on that line: in "item (i) of Theorem 2 is Theorem 1's sigma_i
    c_i < 1" the condition's words are Theorem 1's, not Theorem 2's.
    """
    labels, numbers = _labels(items), _numbers(items)
    by_file: dict[str, list[Citation]] = {}
    for c in cites:
        by_file.setdefault(c.path, []).append(c)
    problems = []
    for c in cites:
        where = f"{c.path}:{c.line}: {c.kind} {', '.join(c.numbers)}"
        missing = [n for n in c.numbers if n not in numbers.get(c.kind, set())]
        if missing:
            problems.append(f"{where}: no {c.kind} {', '.join(missing)} in the paper | {_show(c)}")
            continue
        rivals = [
            (r.offset + r.start - c.offset, r.offset + r.end - c.offset)
            for r in by_file[c.path]
            if r.kind == c.kind
            and c.offset <= r.offset + r.start
            and r.offset + r.end <= c.offset + len(c.text)
        ]
        attached: dict[str, set[str]] = {}
        for concept in CONCEPTS:
            allowed = _allowed(concept, labels, c.kind)
            if not allowed:
                continue
            for m in re.finditer(concept.words, c.text, re.IGNORECASE):
                span = m.span()
                gap = _gap(span, (c.start, c.end))
                if gap <= NEAR and gap <= min(_gap(span, r) for r in rivals):
                    attached[concept.name] = allowed
                    break
        stray = [n for n in c.numbers if attached and n not in set().union(*attached.values())]
        if stray:
            named = "; ".join(f"{name}: {', '.join(sorted(v))}" for name, v in attached.items())
            problems.append(f"{where}: the line names {named} | {_show(c)}")
    return problems


# -- the tests ------------------------------------------------------------------------------------


def test_the_numbering_is_the_papers(paper):
    labels = _labels(paper)

    def cited(label: str) -> str:
        return f"{labels[label].kind} {labels[label].number}"

    # what issue 15 states from the printed paper
    assert cited("ISSassumption") == "Assumption 2"
    assert cited("TheoremCompletenessOfMaximalSolutions") == "Theorem 3"
    assert cited("theoremIndividualInterEventTime") == "Theorem 4"
    assert [
        cited(n) for n in ("generalTriggeringCondition", "MeasurementNoise", "TriggeredInput", "Example")
    ] == [
        "section 7.1",
        "section 7.2",
        "section 7.3",
        "section 8",
    ]
    assert cited("eq:ISSassumptionDerivative") == "equation 13"  # dissipation inequality
    assert cited("eq:stabilityTheoremFlow") == "equation 26"  # nu
    assert cited("eq:SM set") == "equation 36"  # the rate bound E
    assert cited("eq:triggeringRuleRemarkGeneralTriggering") == "equation 45"
    assert [cited("eq:etaEquationTriggeredInput"), cited("eq:inputTriggeringRule")] == [
        "equation 53",
        "equation 54",
    ]
    # counted by hand: (1) is the unlabelled hybrid system of section 2; (29)-(32) in the
    # proof of Proposition 1, (32) unlabelled; (47)-(49) unlabelled; the appendix restarts
    equations = [it.number for it in paper if it.kind == "equation" and it.label is None]
    assert equations == [str(n) for n in range(1, 58)] + [f"A.{n}" for n in range(1, 8)]
    assert cited("eq:system") == "equation 2" and cited("eq: etaEquation") == "equation 14"
    assert cited("eq:triggeringRule") == "equation 15" and cited("eq:observerExample") == "equation 57"
    assert cited("eq:LemmaMultipleChangeSupplyRate") == "equation A.1"  # an aligned pair: one number
    # one counter per \newtheorem: Lemma 1 is in section 6.3, Lemmas 2-3 in the appendix
    assert [
        cited(n) for n in ("Lemma_stopTransmissions", "LemmaMultipleChangeOfSupplyRate", "decayRateLemma")
    ] == [
        "Lemma 1",
        "Lemma 2",
        "Lemma 3",
    ]
    assert cited("TheoremLyapunovSolution") == "Proposition 1"  # between Theorems 1 and 2
    assert cited("RemarkWhyOnlyPractical") == "Remark 3" and cited("remarkFreedomISSgains") == "Remark 1"
    assert cited("tab:SimulationData") == "Table 1" and cited("fig:InterTransmissionsTime") == "Figure 5"
    assert cited("IET") == "section 6.2" and cited("stopTransmissionSubsection") == "section 6.3"


SMALL_PAPER = r"""
\documentclass{article}
\newtheorem{thm}{\textbf{Theorem}}
\newtheorem{lem}[thm]{Lemma}
\newtheorem{defn}{Definition}[section]
\begin{document}
\section{One}\label{s1}
\begin{equation} a \label{e1} \end{equation}
% \begin{equation} commented out \end{equation}
\begin{align} a &= b \label{e2} \\ c &= d \nonumber \\ e &= f \label{e3} \\ \end{align}
\begin{equation} \begin{split} a &= b \\ c &= d \end{split} \label{e4} \end{equation}
\begin{equation*} x \end{equation*}
\[ y \]
\begin{subequations}\label{e5}
\begin{align} a \label{e5a} \\ b \label{e5b} \end{align}
\end{subequations}
\begin{equation} z \tag{$\star$} \label{star} \end{equation}
\begin{thm} \begin{equation} q \label{e6} \end{equation} \label{t1} \end{thm}
\begin{lem}\label{l2} \end{lem}
\subsection{Sub}\label{s11}
\begin{defn}\label{d1} \end{defn}
\appendix
\section{App}\label{sA}
\begin{equation} w \label{eA1} \end{equation}
\end{document}
"""


def test_the_numbering_follows_latex():
    labels = {name: f"{it.kind} {it.number}" for name, it in _labels(number_paper(SMALL_PAPER)).items()}
    assert labels == {
        "s1": "section 1",
        "e1": "equation 1",
        "e2": "equation 2",
        "e3": "equation 3",  # the \nonumber row takes no number
        "e4": "equation 4",  # split: one number
        "e5": "equation 5",
        "e5a": "equation 5a",
        "e5b": "equation 5b",
        "star": "equation $\\star$",
        "e6": "equation 6",
        "t1": "Theorem 1",  # the label after the equation is the theorem's
        "l2": "Lemma 2",  # shares the theorem counter
        "s11": "section 1.1",
        "d1": "Definition 1.1",
        "sA": "section A",
        "eA1": "equation A.1",
    }


def _cited(text: str) -> list[tuple[str, tuple[str, ...]]]:
    return [(c.kind, c.numbers) for c in citations_in(text)]


def test_citations_are_read_as_written():
    assert _cited("eqs. (16)-(17) and eq. 15; the hybrid model (16)--(22)") == [
        ("equation", ("16", "17")),
        ("equation", ("15",)),
        ("equation", tuple(str(n) for n in range(16, 23))),
    ]
    assert _cited("sections 7.1–7.3, §8, Sec. 6.2's bound") == [
        ("section", ("7.1", "7.2", "7.3")),
        ("section", ("8",)),
        ("section", ("6.2",)),
    ]
    assert _cited("Theorems 1-4; Assumptions 2 and 4; Remark 3's copy; Lemma 1, Table 1, Fig. 3") == [
        ("Theorem", ("1", "2", "3", "4")),
        ("Assumption", ("2", "4")),
        ("Remark", ("3",)),
        ("Lemma", ("1",)),
        ("Table", ("1",)),
        ("Figure", ("3",)),
    ]
    # not citations: another word holding "eq", a lower-case table, an item, a file name
    assert _cited("seq 2^64; the table 1 below; Theorem (ii); table1.toml; f(1) - (2)") == []


@pytest.mark.parametrize(
    ("line", "wrong"),
    [
        ("(Theorem 3's minimum inter-event time is gamma_i^-1(eps_i) / E)", True),
        ("(Theorem 4's minimum inter-event time is gamma_i^-1(eps_i) / E)", False),
        ("Assumption 1 is an ISS property with respect to the gap", True),
        ("Assumption 2 is an ISS property with respect to the gap", False),
        ("An input node (section 6.3): sends the plant input", True),
        ("An input node (section 7.3): sends the plant input", False),
        ("`c_u >= 0`, `b_u in [0, 1]`, `sigma_u >= 0` (eq. (52)-(53))", True),
        ("`c_u >= 0`, `b_u in [0, 1]`, `sigma_u >= 0` (eq. (53)-(54))", False),
        ("item (i) of Theorem 2 is Theorem 1's sigma_i c_i < 1", False),
        ("item (i) of Theorem 2 is Theorem 3's sigma_i c_i < 1", True),
        ("Theorem 1's nu = sum_i (1 + d_i c_i) eps_i (eq. (25) holds with it)", True),
        ("certify(problem, iss, E=, noise=) (Theorems 1–3 and the noise condition)", True),
        ("the generalized rule (section 7.1), send-on-delta, and the noise condition of section 6.2", True),
        ("the paper's robot arm (section 7)", True),
        ("eq. (58) of the paper", True),  # the paper has 57 equations before the appendix
        ("Lemma 4", True),
        ("Lemma 1: once the output stays within gamma^{-1}(eps)/2 of a constant", False),
        ("eq. (9) of the paper", False),  # no concept named: any equation that exists
    ],
)
def test_a_wrong_citation_is_caught(paper, line, wrong):
    assert bool(wrong_citations(citations_in(line), paper)) is wrong


def test_the_scan_sees_the_project():
    cites = all_citations()
    where = {c.path.split("/")[0] for c in cites}
    assert {"src", "docs", "tests", "benchmarks", "examples", "README.md"} <= where
    assert len(cites) > 250  # a broken pattern would find few and pass


def test_every_citation_is_the_papers(paper):
    problems = wrong_citations(all_citations(), paper)
    assert not problems, "citations that are not the paper's numbering:\n" + "\n".join(problems)


def test_the_notation_table_is_the_papers_numbering(paper):
    text = (ROOT / "docs" / "notation.md").read_text(encoding="utf-8")
    table = text.split("## The paper's numbering", 1)[1]
    labels = _labels(paper)
    rows = 0
    for line in table.splitlines():
        cells = [cell.strip() for cell in line.strip().strip("|").split("|")]
        names = re.findall(r"`([^`]+)`", cells[1]) if len(cells) >= 3 else []
        if not names:
            continue
        rows += 1
        cited = {(c.kind, n) for c in citations_in(cells[0]) for n in c.numbers}
        assert cited == {(labels[n].kind, labels[n].number) for n in names}, line
    assert rows >= 40
