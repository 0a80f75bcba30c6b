"""A contract type for import-linter (2.17): no import cycle among the modules of a package.

import-linter's own ``acyclic_siblings`` finds cycles between the children of a package (each
child with its descendants squashed), level by level; it does not see a cycle between a
package's ``__init__`` and a module below it, and it reports packages rather than the modules
and lines of a cycle. ``acyclic_modules`` checks the module graph itself: every strongly
connected component of two or more modules (grimp's graph, the same imports import-linter
reads: top-level and function-local ones, ``TYPE_CHECKING`` ones too) is a broken contract,
shown with the line of each import in it. Registered in ``.importlinter``'s
``contract_types``; no ``ignore_imports``: a cycle is fixed, not excused.

Written against import-linter 2.17 (``importlinter.domain.contract.Contract``,
``ContractCheck``, ``fields``, ``importlinter.application.output``) and grimp 3.x
(``ImportGraph.find_children``, ``find_descendants``, ``find_modules_directly_imported_by``,
``get_import_details``), read in their installed sources on 2026-12-02.
"""

from __future__ import annotations

import grimp
from importlinter.application import output
from importlinter.domain import fields
from importlinter.domain.contract import Contract, ContractCheck


def strongly_connected(graph: grimp.ImportGraph, modules: set[str]) -> list[list[str]]:
    """The components of two or more modules of ``modules`` that import each other in a
    circle (Tarjan's algorithm, iterative), each sorted, sorted by their first module."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    on_stack: set[str] = set()
    stack: list[str] = []
    found: list[list[str]] = []
    counter = 0

    def successors(m: str) -> list[str]:
        return sorted(graph.find_modules_directly_imported_by(m) & modules)

    for root in sorted(modules):
        if root in index:
            continue
        work = [(root, iter(successors(root)))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = counter
                    counter += 1
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(successors(child))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                parent = work[-1][0]
                low[parent] = min(low[parent], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    m = stack.pop()
                    on_stack.discard(m)
                    component.append(m)
                    if m == node:
                        break
                if len(component) > 1:
                    found.append(sorted(component))
    return sorted(found)


class AcyclicModulesContract(Contract):
    """``packages``: the packages (with every module below them) whose modules must not
    import each other in a circle."""

    type_name = "acyclic_modules"

    packages = fields.ListField(subfield=fields.StringField())

    def check(self, graph: grimp.ImportGraph, verbose: bool) -> ContractCheck:
        modules: set[str] = set()
        for package in self.packages:  # type: ignore[attr-defined]
            modules |= {package} | graph.find_descendants(package)
        cycles = strongly_connected(graph, modules)
        details = []
        for component in cycles:
            members = set(component)
            lines = []
            for importer in component:
                for imported in sorted(graph.find_modules_directly_imported_by(importer)):
                    if imported in members:
                        for d in graph.get_import_details(importer=importer, imported=imported):
                            lines.append(f"{importer} -> {imported} (l.{d['line_number']})")
            details.append(lines)
        output.verbose_print(verbose, f"{len(modules)} modules, {len(cycles)} cycles")
        return ContractCheck(kept=not cycles, metadata={"cycles": cycles, "details": details})

    def render_broken_contract(self, check: ContractCheck) -> None:
        for component, lines in zip(
            check.metadata["cycles"], check.metadata["details"], strict=True
        ):
            output.print_error(f"Import cycle among {', '.join(component)}:", bold=True)
            for line in lines:
                output.indent_cursor()
                output.print_error(line, bold=False)
            output.new_line()
