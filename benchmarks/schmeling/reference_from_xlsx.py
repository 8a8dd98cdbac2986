"""Turn the published slab-tip curves of Schmeling et al. (2008), case 1, into ``reference.csv``.

The curves come as a spreadsheet, ``zslab-case1-best-reformatted.xlsx``, in G-ADOPT's repository
(github.com/g-adopt/g-adopt, tests/multi_material/data; MIT licence, Copyright (c) 2021 G-ADOPT
Authors). Its sheet "Tabelle1" holds one (t [Myr], slab-tip depth [km], trench position [km])
column triple per code and viscosity mixing; the sheet "zslabmodel5" holds FDCON 561x141 with
geometric mixing. This script reads the spreadsheet with the standard library only (an .xlsx is
a zip of XML) and writes one row per (code, time)::

    python -m benchmarks.schmeling.reference_from_xlsx zslab-case1-best-reformatted.xlsx

The result is committed; the script says how it was made.
"""

from __future__ import annotations

import csv
import re
import sys
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
NS = {"m": "http://schemas.openxmlformats.org/spreadsheetml/2006/main"}
SHEETS = {"Tabelle1": "xl/worksheets/sheet2.xml", "zslabmodel5": "xl/worksheets/sheet3.xml"}


def _cells(book: zipfile.ZipFile, path: str, strings: list[str]) -> dict[int, dict[int, str | float]]:
    """The sheet's values by (1-based row, 0-based column)."""
    rows: dict[int, dict[int, str | float]] = {}
    for cell in ET.fromstring(book.read(path)).iter(f"{{{NS['m']}}}c"):
        value = cell.find("m:v", NS)
        if value is None or value.text is None:
            continue
        letters = re.match(r"[A-Z]+", cell.get("r", "")).group()
        column = 0
        for letter in letters:
            column = column * 26 + ord(letter) - ord("A") + 1
        row = int(cell.get("r", "")[len(letters):])
        rows.setdefault(row, {})[column - 1] = strings[int(value.text)] if cell.get("t") == "s" else float(value.text)
    return rows


def _pairs(rows: dict[int, dict[int, str | float]], column: int) -> list[tuple[float, float]]:
    """The numeric (time, depth) pairs of columns ``column`` and ``column + 1``."""
    pairs = []
    for row in sorted(rows):
        t, z = rows[row].get(column), rows[row].get(column + 1)
        if isinstance(t, float) and isinstance(z, float):
            pairs.append((t, z))
    return pairs


def main(xlsx: Path, out: Path = HERE / "reference.csv") -> None:
    with zipfile.ZipFile(xlsx) as book:
        strings = [si.findtext("m:t", "", NS) for si in ET.fromstring(book.read("xl/sharedStrings.xml")).findall("m:si", NS)]
        table = _cells(book, SHEETS["Tabelle1"], strings)
        fdcon = _cells(book, SHEETS["zslabmodel5"], strings)
    curves = {str(name): _pairs(table, column) for column, name in table[3].items() if isinstance(name, str)}
    curves["FDCON 561x141 geom"] = _pairs(fdcon, 1)
    with open(out, "w", newline="") as f:
        f.write("# Schmeling et al. (2008), PEPI 171, 198-223, case 1: slab-tip depth below the surface against time,\n"
                "# per code, grid and viscosity mixing (geom/arith/harm). From zslab-case1-best-reformatted.xlsx in\n"
                "# github.com/g-adopt/g-adopt tests/multi_material/data (MIT licence, Copyright (c) 2021 G-ADOPT\n"
                "# Authors); made by reference_from_xlsx.py.\n")
        writer = csv.writer(f)
        writer.writerow(["code", "time_Myr", "depth_km"])
        for name, pairs in curves.items():
            for t, z in pairs:
                writer.writerow([name, f"{t:.6g}", f"{z:.6g}"])
    print(f"wrote {out}: {len(curves)} curves, " + ", ".join(f"{n} ({len(p)})" for n, p in curves.items()))


if __name__ == "__main__":
    main(Path(sys.argv[1]))
