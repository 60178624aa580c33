"""Write the simulated false-verdict rates and interval coverages into docs/report.md's generated block.

    python scripts/stats_calibration.py                          # print the block
    python scripts/stats_calibration.py --write docs/report.md   # replace it between the markers

The block between ``<!-- generated: stats-calibration -->`` and ``<!-- /generated: stats-calibration -->`` is
:func:`morfic_cli.report.simulate.calibration_markdown` (2000 draws per cell at 3 and 5 seeds; about 2 s).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from morfic_cli.report.simulate import DRAWS, calibration_markdown

BEGIN, END = "<!-- generated: stats-calibration -->", "<!-- /generated: stats-calibration -->"


def main(argv: list[str] | None = None) -> int:
    """Print the block, or write it between ``--write``'s markers; 0."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--write", type=Path, default=None, help="markdown file whose marked block to replace")
    p.add_argument("--draws", type=int, default=DRAWS, help="simulated stores per cell")
    args = p.parse_args(argv)
    block = calibration_markdown(draws=args.draws)
    if args.write is None:
        print(block)
        return 0
    text = args.write.read_text()
    if BEGIN not in text or END not in text:
        raise SystemExit(f"Error: {args.write} has no {BEGIN} ... {END} markers; add them where the block goes.")
    head, rest = text.split(BEGIN, 1)
    _, tail = rest.split(END, 1)
    args.write.write_text(f"{head}{BEGIN}\n{block}\n{END}{tail}")
    print(f"{args.write}: stats calibration written")
    return 0


if __name__ == "__main__":
    sys.exit(main())
