"""The package's import graph: no private name crosses a module boundary, no two modules import
each other, and the heavy libraries load only where they are used (docs/architecture.md)."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

PKG = Path(__file__).resolve().parents[1] / "mocapfj"


def _module_name(path: Path) -> str:
    parts = path.relative_to(PKG.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imports(path: Path) -> list[tuple[str, tuple[str, ...]]]:
    """(imported mocapfj module, names taken from it) for every import statement in the file,
    including those inside functions (TYPE_CHECKING-only imports too)."""
    mod = _module_name(path)
    package = mod if path.name == "__init__.py" else mod.rsplit(".", 1)[0]
    out = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if target.split(".")[0] != "mocapfj":
                continue
            names = tuple(a.name for a in node.names)
            # "from . import x" imports the submodule x
            subs = [f"{target}.{n}" for n in names if (PKG.parent / Path(*f"{target}.{n}".split("."))).with_suffix(".py").exists()
                    or (PKG.parent / Path(*f"{target}.{n}".split(".")) / "__init__.py").exists()]
            for s in subs:
                out.append((s, ()))
            rest = tuple(n for n in names if f"{target}.{n}" not in subs)
            if rest:
                out.append((target, rest))
        elif isinstance(node, ast.Import):
            for a in node.names:
                if a.name.split(".")[0] == "mocapfj":
                    out.append((a.name, ()))
    return out


FILES = sorted(PKG.rglob("*.py"))
GRAPH = {_module_name(p): _imports(p) for p in FILES}


def test_no_private_name_is_imported_across_modules():
    bad = [f"{mod} imports {n} from {target}" for mod, imps in GRAPH.items() for target, names in imps
           for n in names if n.startswith("_") and not n.startswith("__") and target != mod]
    assert not bad, "\n".join(bad)


def test_no_two_modules_import_each_other():
    edges = {mod: {t for t, _ in imps if t != mod and t in GRAPH} for mod, imps in GRAPH.items()}
    # a package's __init__ re-exporting its own modules is how packages are built; the submodule
    # importing a sibling through the package is not a mutual import of two files
    cycles = sorted({tuple(sorted((a, b))) for a, targets in edges.items() for b in targets
                     if a in edges.get(b, set()) and not (b.startswith(a + ".") or a.startswith(b + "."))})
    assert not cycles, cycles


def test_help_and_import_do_not_load_heavy_libraries():
    code = ("import sys, mocapfj, mocapfj.cli, mocapfj.ident, mocapfj.joints, mocapfj.dynamics, mocapfj.discover, "
            "mocapfj.pipeline; print(','.join(m for m in ('pinocchio', 'rerun', 'matplotlib', 'cv2', 'trimesh', "
            "'dask') if m in sys.modules))")
    loaded = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()
    assert loaded == "", f"imported at start-up: {loaded}"
