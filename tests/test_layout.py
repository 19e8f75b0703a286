"""The package's shape: docs/layout.md names every top-level folder and module of
core/ (the estim package), in the order of the layers contract that lint-imports checks."""

import re
from pathlib import Path

import pytest

tomllib = pytest.importorskip("tomllib")        # Python 3.11+

ROOT = Path(__file__).resolve().parents[1]


def layout_entries() -> list[str]:
    text = (ROOT / "docs" / "layout.md").read_text()
    block = text[text.index("# Layout"):]
    block = block[block.index("```\n") + 4:]
    block = block[:block.index("```")]
    names = []
    for line in block.splitlines():
        match = re.match(r"  (\S.*?)(?:   |$)", line)      # an entry of core/, indented 2
        if match and not line.startswith("   "):
            names += match.group(1).split()
    return names


def test_readme_layout_names_every_folder_and_module_of_the_package():
    on_disk = {p.name + ("/" if p.is_dir() else "") for p in (ROOT / "core").iterdir()
               if not p.name.startswith(("_", ".")) and (p.is_dir() or p.suffix == ".py")}
    assert sorted(layout_entries()) == sorted(on_disk)


def test_readme_layout_lists_the_layers_bottom_up_as_the_contract_does():
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["importlinter"]
    layers = next(c for c in config["contracts"] if c["type"] == "layers")
    contract = [name.strip() for layer in reversed(layers["layers"])
                for name in re.split(r"[|:]", layer)]
    listed = [name.rstrip("/").removesuffix(".py") for name in layout_entries()]
    in_contract = [name for name in listed if name in contract]
    position = {name: i for i, layer in enumerate(reversed(layers["layers"]))
                for name in (n.strip() for n in re.split(r"[|:]", layer))}
    assert [position[n] for n in in_contract] == sorted(position[n] for n in in_contract)
    assert set(in_contract) == {n for n in contract if not n.startswith("_")} - {"cli"}


def test_the_package_top_level_holds_at_most_six_modules():
    modules = [p.name for p in (ROOT / "core").glob("*.py")]
    assert len(modules) <= 6, modules
