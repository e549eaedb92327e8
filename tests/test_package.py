import etobs


def test_public_api_is_exported():
    for name in etobs.__all__:
        assert hasattr(etobs, name), name
    assert etobs.__version__ == "0.1.0"


def test_each_public_name_is_written_once_in_the_stub_and_is_the_object_of_its_module():
    import ast
    import importlib
    from pathlib import Path

    import pytest

    stub = Path(etobs.__file__).with_suffix(".pyi")
    imports = [n for n in ast.parse(stub.read_text()).body if isinstance(n, ast.ImportFrom)]
    names = [(n.module, a.name, a.asname) for n in imports for a in n.names]
    assert all(asname == name for _, name, asname in names), "the stub re-exports as `X as X`"
    assert len({name for _, name, _ in names}) == len(names), "a name listed twice"
    for module, name, _ in names:
        assert getattr(etobs, name) is getattr(importlib.import_module(module), name), name
    assert set(etobs.__all__) <= set(dir(etobs))
    with pytest.raises(AttributeError, match=r"module 'etobs' has no attribute 'simulat'"):
        etobs.simulat  # noqa: B018


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


def test_the_public_names_are_read_from_a_zip_too(tmp_path):
    # the stub is read as package data: etobs imported from a zip archive has its names
    import subprocess
    import sys
    import zipfile
    from pathlib import Path

    src = Path(etobs.__file__).parent
    archive = tmp_path / "etobs.zip"
    with zipfile.ZipFile(archive, "w") as z:
        for f in src.rglob("*"):
            if f.suffix in (".py", ".pyi") and "__pycache__" not in f.parts:
                z.write(f, Path("etobs") / f.relative_to(src))
    code = (
        "import sys; sys.meta_path[:] = [f for f in sys.meta_path if 'editable' not in repr(f).lower()]; "
        f"sys.path.insert(0, {str(archive)!r}); import etobs; "
        "print(etobs.__file__.startswith(sys.path[0]), len(etobs.__all__), etobs.Linear.__name__)"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True
    )
    assert out.stdout.split() == ["True", str(len(etobs.__all__)), "Linear"]
