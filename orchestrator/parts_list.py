"""Provides the parts list of a pulled leg's robot: `parts.csv` (each part by number and name,
per leg and for the six legs as mounted, and what it serves) and `parts.xml` (a BrickLink
wanted list of the robot's parts, as BrickLink's "Upload" page reads it).

BrickLink's wanted-list XML: an `INVENTORY` root with one `ITEM` per part and colour, each
holding `ITEMTYPE` (P: a part), `ITEMID` (BrickLink's item number, `technic_parts.json`),
`COLOR` (BrickLink's colour id) and `MINQTY`.
"""

from __future__ import annotations

import csv
import io
import xml.etree.ElementTree as ET

from linkevo.sim.robot.parts import Part, PartsBuild, catalogue, mounted_joints

BRICKLINK_COLOURS = {"beam": 86, "driver": 86, "pin": 86, "axle": 11, "bush": 86}
"""BrickLink colour ids: light bluish grey (86) for beams, frictionless pins and bushes,
black (11) for axles; friction pins are black too (`colour`)."""
CSV_COLUMNS = ("part", "name", "bricklink", "per_leg", "robot", "serves")


def colour(part: Part) -> int:
    """The BrickLink colour id a part is ordered in."""
    return 11 if part.friction else BRICKLINK_COLOURS[part.kind]


def robot_counts(build: PartsBuild, spacers: dict[str, int]) -> dict[str, int]:
    """Returns each part number's count for the six legs, each mounted on its slot's
    spacers (`sim.robot.mounting`)."""
    out: dict[str, int] = {}
    for n in spacers.values():
        for number, count in build.counts(n).items():
            out[number] = out.get(number, 0) + count
    return out


def serves(build: PartsBuild) -> dict[str, list[str]]:
    """Returns what each part number serves in one leg: beams by their bar's first linkage
    beam (b0, b3, ...), fasteners and fillers by node (node 4), lock pins by bar."""
    cat = catalogue()
    out: dict[str, list[str]] = {}

    def note(part: Part, what: str) -> None:
        out.setdefault(part.number, [])
        if what not in out[part.number]:
            out[part.number].append(what)

    for piece in build.pieces:
        note(piece.part, f"b{piece.beam}")
    for joint in mounted_joints(build, 0):
        note(joint.fastener, f"node {joint.node}")
        for part, _ in joint.fillers:
            note(part, f"node {joint.node}")
    first = {piece.bar: piece.beam for piece in reversed(build.pieces)}
    for bar, _ in build.locks:
        note(cat.pin(2, friction=True), f"joined bar b{first[bar]}")
    note(build.driver, "motor")
    note(cat.pin(2, friction=True), "motor")
    return out


def parts_rows(build: PartsBuild, spacers: dict[str, int]) -> list[dict]:
    """Returns one row per part (`CSV_COLUMNS`), beams first, then by part number."""
    cat = catalogue()
    per_leg, robot, used = build.counts(0), robot_counts(build, spacers), serves(build)
    kinds = {"beam": 0, "driver": 1, "pin": 2, "axle": 3, "bush": 4}
    numbers = sorted(robot, key=lambda n: (kinds[cat.part(n).kind], cat.part(n).size, n))
    return [
        {
            "part": n,
            "name": cat.part(n).name,
            "bricklink": cat.part(n).bricklink,
            "per_leg": per_leg.get(n, 0),
            "robot": robot[n],
            "serves": ", ".join(used.get(n, ["mounting spacers"])),
        }
        for n in numbers
    ]


def parts_csv(rows: list[dict]) -> str:
    """The rows (`parts_rows`) as CSV."""
    out = io.StringIO()
    writer = csv.DictWriter(out, fieldnames=CSV_COLUMNS, lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    return out.getvalue()


def parts_xml(rows: list[dict]) -> str:
    """The robot's parts (`parts_rows`, column `robot`) as a BrickLink wanted list."""
    cat = catalogue()
    root = ET.Element("INVENTORY")
    for row in rows:
        item = ET.SubElement(root, "ITEM")
        ET.SubElement(item, "ITEMTYPE").text = "P"
        ET.SubElement(item, "ITEMID").text = row["bricklink"]
        ET.SubElement(item, "COLOR").text = str(colour(cat.part(row["part"])))
        ET.SubElement(item, "MINQTY").text = str(row["robot"])
        ET.SubElement(item, "REMARKS").text = row["name"]
    ET.indent(root)
    return ET.tostring(root, encoding="unicode") + "\n"
