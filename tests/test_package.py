import etobs


def test_public_api_is_exported():
    for name in etobs.__all__:
        assert hasattr(etobs, name), name
    assert etobs.__version__ == "0.1.0"


#: The paper's authors, in order: ../shared/paper/decentralized-event-triggered-estimation.tex,
#: its \author lines (Petri, Postoyan, Astolfi, Nešić, Heemels).
PAPER_AUTHORS = ["Petri", "Postoyan", "Astolfi", "Nešić", "Heemels"]


def test_the_paper_is_credited_to_its_authors_in_the_readme_and_the_citation_file():
    from pathlib import Path

    root = Path(__file__).parents[1]
    readme = root.joinpath("README.md").read_text(encoding="utf-8")
    assert ", ".join(PAPER_AUTHORS) in readme
    citation = root.joinpath("CITATION.cff").read_text(encoding="utf-8")
    assert [line.split(":", 1)[1].strip() for line in citation.splitlines() if "family-names:" in line] == (
        PAPER_AUTHORS
    )
    license_text = root.joinpath("LICENSE").read_text(encoding="utf-8")
    assert license_text.startswith("BSD 3-Clause License")  # pyproject says BSD-3-Clause
