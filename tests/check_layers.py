#!/usr/bin/env python3
# SPDX-License-Identifier: GPL-3.0-or-later
"""The layer check: no include from a lower layer to a higher one, and rooms kept apart.

Each folder of src/ and include/physreg/ is a layer with a rank; a file may include headers of its
own rank or below. apps/ and python/ sit on top. A back-edge that is not in KNOWN_BACK_EDGES fails
the check, naming the file, the line and the two layers; a listed back-edge that has gone is
reported too, so the list only shrinks. Run: check_layers.py SOURCE_DIR (ctest layers.no_back_edges).

Includes are read in three forms: "physreg/LAYER/…", a private header by its layer's path
("mechanics/detail/x.hpp", from src/) and relative ones ("detail/x.hpp"), resolved against the
including file's folder. Two more rules:
- a private header (under src/, e.g. src/io/detail/) is included only from its own layer, by its
  layer's path, never by "../";
- the rooms of ROOMS (sub-folders of a layer, one concept each) do not include one another: they
  share through the layer's top-level files and its detail/ folder.
"""
import pathlib
import re
import sys

# Lowest first. Layers of one rank may include each other.
RANKS = {
    "core": 0,
    "image": 1, "model": 1,
    "mesh": 2,
    "io": 3, "field": 3,
    "mechanics": 4,
    "evaluation": 5,
    "figures": 6, "registration": 6,  # figures draw evaluation's results; evaluation draws nothing
    "phantom": 7,       # the experiment generator: above the registration it is used to judge
    "live": 7,          # the OpenIGTLink wire and the served session: above the registrations they serve
    "apps": 8,
    "python": 9,
}
# Back-edges that exist today, to be removed (issue "The house", item 1), never added to.
KNOWN_BACK_EDGES = set()  # none left: the dataset reader is in io/, label roles and loads in model/
# Rooms that must not include one another: each paper's pipeline stands on its own.
ROOMS = {"registration": {"compression", "surface", "images"}}
# Private headers reached from another layer, to be removed, never added to.
KNOWN_PRIVATE_REACH = {
    # The ITK baselines share the ITK bridge's plain image types (both sit in physreg_itk_* object
    # libraries that see ITK's headers); moving the bridge to a layer of its own removes it.
    ("src/registration/detail/itk_baselines.hpp", "src/io/detail/itk_bridge.hpp"),
}
INCLUDE = re.compile(r'^\s*#\s*include\s+"([^"]+)"')


def layer_of(relative: pathlib.PurePosixPath):
    parts = relative.parts
    if parts[0] == "src" and len(parts) > 2:
        return parts[1]
    if parts[:2] == ("include", "physreg") and len(parts) > 3:
        return parts[2]
    if parts[0] in ("apps", "python"):
        return parts[0]
    return None


def room_of(relative: pathlib.PurePosixPath):
    """(layer, room) of a file: the sub-folder below its layer, or None at the layer's top."""
    parts = relative.parts
    if parts[0] == "src" and len(parts) > 3:
        return parts[1], parts[2]
    if parts[:2] == ("include", "physreg") and len(parts) > 4:
        return parts[2], parts[3]
    return layer_of(relative), None


def resolve(root: pathlib.Path, path: pathlib.Path, text: str):
    """The included file, relative to the source root: physreg/… under include/, else relative to
    the including file (and its folder's generated or src counterparts); None for system headers."""
    if text.startswith("physreg/"):
        return pathlib.PurePosixPath("include") / text
    if not (path.parent / text).exists() and (root / "src" / text).exists():
        return pathlib.PurePosixPath("src") / text  # a private header by its layer's path
    candidate = (path.parent / text).resolve()
    try:
        return pathlib.PurePosixPath(candidate.relative_to(root).as_posix())
    except ValueError:
        return None


def main(root: pathlib.Path) -> int:
    problems, seen, reached = [], set(), set()
    files = [p for d in ("src", "include", "apps", "python") for p in (root / d).rglob("*")
             if p.suffix in (".cpp", ".hpp", ".h", ".in") and p.is_file()]
    for path in sorted(files):
        relative = pathlib.PurePosixPath(path.relative_to(root).as_posix())
        layer = layer_of(relative)
        if layer is None:
            continue
        if layer not in RANKS:
            problems.append(f"{relative}: folder '{layer}' has no rank in tests/check_layers.py (add it to RANKS)")
            continue
        for number, line in enumerate(path.read_text(errors="replace").splitlines(), 1):
            match = INCLUDE.match(line)
            if not match:
                continue
            if match.group(1).startswith("../") and relative.parts[0] in ("src", "include"):
                problems.append(f"{relative}:{number}: reaches a header by '../' ({match.group(1)}): name it by its layer's path "
                                f"(\"mechanics/detail/x.hpp\" for a private header, \"physreg/…\" for a public one)")
            included = resolve(root, path, match.group(1))
            if included is None or layer_of(included) is None:
                continue  # a header of another library, or one of the same folder outside the layers
            target = layer_of(included)
            if included.parts[0] == "src" and target != layer:
                key = (str(relative), str(included))
                reached.add(key)
                if key not in KNOWN_PRIVATE_REACH:
                    problems.append(f"{relative}:{number}: includes the private header {included} of layer '{target}' "
                                    f"(private headers serve their own layer only)")
            room, target_room = room_of(relative)[1], room_of(included)[1]
            if (target == layer and layer in ROOMS and room in ROOMS[layer] and target_room in ROOMS[layer] and room != target_room):
                problems.append(f"{relative}:{number}: room '{layer}/{room}' includes room '{layer}/{target_room}': rooms share "
                                f"through the layer's top-level files or detail/ ({included})")
            if target not in RANKS:
                problems.append(f"{relative}:{number}: includes unknown layer '{target}'")
            elif RANKS[target] > RANKS[layer]:
                key = (str(relative), target)
                seen.add(key)
                if key not in KNOWN_BACK_EDGES:
                    problems.append(f"{relative}:{number}: layer '{layer}' (rank {RANKS[layer]}) includes the higher layer "
                                    f"'{target}' (rank {RANKS[target]}): {line.strip()}")
    for key in sorted(KNOWN_BACK_EDGES - seen):
        problems.append(f"{key[0]} no longer includes '{key[1]}': remove it from KNOWN_BACK_EDGES")
    for key in sorted(KNOWN_PRIVATE_REACH - reached):
        problems.append(f"{key[0]} no longer includes '{key[1]}': remove it from KNOWN_PRIVATE_REACH")
    for p in problems:
        print(p)
    print(f"layers: {len(files)} files checked, {len(problems)} problem(s), {len(seen & KNOWN_BACK_EDGES)} known back-edge(s) and "
          f"{len(reached & KNOWN_PRIVATE_REACH)} known private reach(es) left")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main(pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else ".").resolve()))
