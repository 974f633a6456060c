"""Import cycles in a graph of modules (module -> the modules it imports), for the layer tests of each package."""

from __future__ import annotations


def cycles(graph: dict[str, set[str]]) -> list[str]:
    """Every cycle a depth-first walk meets, as ``a -> b -> ... -> a`` (empty: the graph has none)."""
    state: dict[str, int] = {}
    found: list[str] = []

    def walk(m: str, stack: list[str]) -> None:
        state[m] = 1
        for t in sorted(graph.get(m, ())):
            if state.get(t) == 1:
                found.append(" -> ".join(stack[stack.index(t):] + [t]))
            elif t not in state:
                walk(t, stack + [t])
        state[m] = 2

    for m in sorted(graph):
        if m not in state:
            walk(m, [m])
    return found
