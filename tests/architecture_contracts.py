"""A custom import-linter contract: no private name is used across modules.

import-linter checks which modules import which; it does not look at names. This contract type
(``private_names``) reads the source of every module in ``source_packages`` and reports each use
of another module's private name (a leading underscore, dunders excepted):

* ``from m import _name`` and ``import m._private`` / ``from m._private import x`` (a private
  module component), unless the importer is inside that private module's parent package (the
  rule of import-linter's own ``private_modules`` contract);
* ``alias._name`` where ``alias`` is bound by an import to a module;
* ``obj._name`` where ``_name`` is a function, class, method or attribute that some other
  module of the ``root_packages`` defines and the module itself does not (``self`` and ``cls``
  are the module's own); this catches ``ex._init_world`` on an object whose class lives in
  another module. Private attributes of third-party objects (MJX's documented
  ``data._impl``) are not defined in the root packages and are not reported.

Configuration (INI)::

    [importlinter]
    root_packages = benchmarks
        peghole_mjx
    contract_types =
        private_names: tests.architecture_contracts.PrivateNamesContract

    [importlinter:contract:benchmarks-private-names]
    name = No benchmarks module uses another module's private name
    type = private_names
    source_packages = benchmarks
    allow = (optional) module names whose private names may be used, one per line

Relies on import-linter 2.17's custom contract API (``importlinter.domain.contract.Contract``,
``fields``, ``importlinter.application.output``; read from the installed source, 2026-12-02).
"""

from __future__ import annotations

import ast
import importlib.util
from dataclasses import dataclass
from pathlib import Path

import grimp
from importlinter.application import output
from importlinter.domain import fields
from importlinter.domain.contract import Contract, ContractCheck


def is_private(name: str) -> bool:
    """A leading underscore that is not a dunder (``__init__``, ``__main__`` are public)."""
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


@dataclass(frozen=True, order=True)
class Use:
    """One use of a private name: where, and what."""

    module: str
    line: int
    what: str


def module_file(module: str) -> Path | None:
    """The source file of ``module``, found from its root package's location without
    importing the module itself (only the root package's spec is looked up)."""
    root, *rest = module.split(".")
    spec = importlib.util.find_spec(root)
    if spec is None or not spec.submodule_search_locations:
        return None
    base = Path(next(iter(spec.submodule_search_locations))).joinpath(*rest)
    for candidate in (base.with_suffix(".py"), base / "__init__.py"):
        if candidate.is_file():
            return candidate
    return None


def _absolute(module: str, is_package: bool, node: ast.ImportFrom) -> str:
    """The absolute module of a (possibly relative) ``from ... import``."""
    if not node.level:
        return node.module or ""
    parts = module.split(".")
    base = parts if is_package else parts[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def _private_module_use(importer: str, imported: str) -> str | None:
    """The private component of ``imported`` that ``importer`` may not reach, or None."""
    parts = imported.split(".")
    for i, part in enumerate(parts):
        if is_private(part):
            parent = ".".join(parts[:i])
            if importer == parent or importer.startswith(parent + "."):
                return None
            return ".".join(parts[: i + 1])
    return None


def defined_private_names(tree: ast.Module) -> set[str]:
    """Private functions, classes, methods and attributes a module defines (at any depth,
    ``self._x = ...`` included)."""
    out: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
            out.add(node.name)
        elif isinstance(node, ast.Assign | ast.AnnAssign | ast.AugAssign):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            for t in targets:
                for sub in ast.walk(t):
                    if isinstance(sub, ast.Name):
                        out.add(sub.id)
                    elif isinstance(sub, ast.Attribute):
                        out.add(sub.attr)
    return {n for n in out if is_private(n)}


def private_uses(
    module: str, tree: ast.Module, is_package: bool, modules: set[str], defined: dict[str, set]
) -> list[Use]:
    """Every use in ``module`` (its parsed ``tree``) of another module's private name.

    ``modules``: the names of all modules in the graph; ``defined``: private name -> the
    modules that define it.
    """
    uses: list[Use] = []
    module_aliases: dict[str, str] = {}
    own = {m for m, ms in defined.items() if module in ms}
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                if bad := _private_module_use(module, a.name):
                    uses.append(Use(module, node.lineno, f"import {bad}"))
                bound = a.asname or a.name.split(".")[0]
                module_aliases[bound] = a.name if a.asname else a.name.split(".")[0]
        elif isinstance(node, ast.ImportFrom):
            src = _absolute(module, is_package, node)
            if bad := _private_module_use(module, src):
                uses.append(Use(module, node.lineno, f"from {bad} import ..."))
            for a in node.names:
                full = f"{src}.{a.name}"
                if full in modules:  # a submodule: private only where its path is
                    module_aliases[a.asname or a.name] = full
                    if not bad and (sub := _private_module_use(module, full)):
                        uses.append(Use(module, node.lineno, f"import {sub}"))
                elif is_private(a.name) and src != module:
                    uses.append(Use(module, node.lineno, f"from {src} import {a.name}"))
    for node in ast.walk(tree):
        if not (isinstance(node, ast.Attribute) and is_private(node.attr)):
            continue
        if not isinstance(node.value, ast.Name) or node.value.id in ("self", "cls"):
            continue
        target = module_aliases.get(node.value.id)
        if target is not None and target != module:
            uses.append(Use(module, node.lineno, f"{target}.{node.attr}"))
        elif target is None and node.attr in defined and node.attr not in own:
            where = ", ".join(sorted(defined[node.attr]))
            uses.append(Use(module, node.lineno, f"{node.value.id}.{node.attr} ({where})"))
    return sorted(set(uses))


class PrivateNamesContract(Contract):
    """No module of ``source_packages`` uses a private name of another module."""

    type_name = "private_names"

    source_packages = fields.ListField(subfield=fields.StringField())
    allow = fields.ListField(subfield=fields.StringField(), required=False)

    def check(self, graph: grimp.ImportGraph, verbose: bool) -> ContractCheck:
        modules = set(graph.modules)
        trees: dict[str, tuple[ast.Module, bool]] = {}
        defined: dict[str, set[str]] = {}
        for module in sorted(modules):
            path = module_file(module)
            if path is None:
                continue
            tree = ast.parse(path.read_text(), filename=str(path))
            trees[module] = (tree, path.name == "__init__.py")
            for name in defined_private_names(tree):
                defined.setdefault(name, set()).add(module)
        allowed = set(self.allow or [])
        sources = list(self.source_packages)  # type: ignore[arg-type]
        uses: list[Use] = []
        for module, (tree, is_package) in sorted(trees.items()):
            if not any(module == s or module.startswith(s + ".") for s in sources):
                continue
            for use in private_uses(module, tree, is_package, modules, defined):
                if not any(a in use.what for a in allowed):
                    uses.append(use)
        return ContractCheck(kept=not uses, metadata={"uses": uses})

    def render_broken_contract(self, check: ContractCheck) -> None:
        output.print_error("Private names used outside the module that defines them:", bold=False)
        output.new_line()
        for use in check.metadata["uses"]:
            output.print_error(f"- {use.module} (l.{use.line}): {use.what}", bold=False)
        output.new_line()
