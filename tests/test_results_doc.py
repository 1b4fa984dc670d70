"""docs/RESULTS.md is written whole by `headway eval ... --out docs/RESULTS.md`: its header names that command, in
the form the generator writes, so running the command named regenerates the document."""
import re
import shlex
from pathlib import Path

from app.cli import build_parser
from app.eval import report, results_doc

RESULTS = Path(__file__).resolve().parent.parent / "docs" / "RESULTS.md"


def _command_in(text: str) -> str:
    m = re.search(r"```sh\n(headway eval [^\n]+)\n```", text)
    assert m, "docs/RESULTS.md names no `headway eval` command in a sh block at its head"
    return m.group(1)


def _command_of(cmd: str) -> str:
    """The command the generator writes for the arguments `cmd` parses into."""
    args = build_parser().parse_args(shlex.split(cmd)[1:])
    parts = tuple(args.parts.split(",")) if args.parts else report.PARTS
    scenarios = args.scenarios.split(",") if args.scenarios else None
    return results_doc.command(report.presets_of(args.pipeline), parts, report.PARTS, args.out, args.data,
                               args.config, scenarios)


def test_results_header_is_the_generators_and_names_the_command_that_writes_it():
    text = RESULTS.read_text()
    cmd = _command_in(text)
    assert _command_of(cmd) == cmd, "the command in docs/RESULTS.md is not the one the generator would write"
    assert shlex.split(cmd)[-2:] == ["--out", "docs/RESULTS.md"], cmd
    assert text.startswith(results_doc.header(cmd)), (
        "docs/RESULTS.md does not open with the generator's header; regenerate it with: " + cmd)


def test_the_command_leaves_out_defaults_and_keeps_what_changes_the_figures():
    assert results_doc.command(["default"], report.PARTS, report.PARTS, "docs/RESULTS.md") == \
        "headway eval --pipeline default --out docs/RESULTS.md"
    cmd = results_doc.command(["default", "thesis"], ("synthetic", "fcw"), report.PARTS, "R.md", "/data",
                              "car.yaml", ["cut_in"])
    assert cmd == ("headway eval --pipeline default,thesis --parts synthetic,fcw --scenarios cut_in --data /data "
                   "--config car.yaml --out R.md")
    assert _command_of(cmd) == cmd


def test_eval_writes_the_document_with_that_header(tmp_path, monkeypatch):
    """A small run (the cost part of one preset) through the CLI writes the whole document at --out FILE.md."""
    from app import cli

    monkeypatch.chdir(tmp_path)
    out = tmp_path / "R.md"
    assert cli.main(["eval", "--pipeline", "thesis", "--parts", "cost", "--out", str(out)]) == 0
    text = out.read_text()
    cmd = f"headway eval --pipeline thesis --parts cost --out {shlex.quote(str(out))}"
    assert text.startswith(results_doc.header(cmd)), text[:400]
    assert "## Preset `thesis`" in text and "Cost per frame" in text
    assert (tmp_path / "reports" / "eval-thesis" / "report.json").exists()


def test_an_out_that_is_not_markdown_is_still_a_report_folder(tmp_path):
    assert not results_doc.is_document(str(tmp_path / "reports"))
    assert results_doc.is_document("docs/RESULTS.md")

