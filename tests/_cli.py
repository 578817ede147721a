"""What the CLI tests share: run a command that must be refused, and what "nothing written" compares."""

from __future__ import annotations

from pathlib import Path

from garage_mj.cli import main


def one_line_error(capsys, argv: list[str]) -> str:
    """Run the CLI in-process; assert exit status 2 and exactly one error line (after argparse's usage, for a
    bad option), no traceback and no raw terminal escape; return that line."""
    try:
        rc = main(argv)
    except SystemExit as exc:  # argparse: its usage, then one error line
        rc = exc.code
    out, err = capsys.readouterr()
    lines = [ln for ln in err.splitlines() if ln.strip() and not ln.startswith("usage:") and not ln.startswith(" ")]
    assert rc == 2, (rc, out[-400:], err[-2000:])
    assert "Traceback" not in err + out, err
    assert "\x1b" not in err + out, err  # no terminal escape printed raw
    assert len(lines) == 1 and "error: " in lines[0], err
    return lines[0]


def snapshot(*roots: Path) -> dict[str, bytes]:
    """Every file and folder under ``roots`` (or the file itself) with its bytes (a folder as ``<dir>``);
    missing roots are empty: what "nothing created or changed" compares."""
    out: dict[str, bytes] = {}
    for root in roots:
        if root.is_file():
            out[str(root)] = root.read_bytes()
        elif root.exists():
            for p in sorted(root.rglob("*")):
                out[str(p)] = p.read_bytes() if p.is_file() else b"<dir>"
    return out
