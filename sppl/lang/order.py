"""The order of a class's declarations: what depends on what, circles, and an order where
each declaration comes after what it uses."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from . import ast


def strongly_connected(nodes: list[str], deps: Mapping[str, list[str]]) -> list[set[str]]:
    """Tarjan's strongly connected components of the dependency graph."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[set[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in deps.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = set()
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.add(w)
                if w == v:
                    break
            found.append(component)

    for v in nodes:
        if v not in index:
            visit(v)
    return found


def cycle_path(start: str, deps: Mapping[str, list[str]], component: set[str]) -> list[str]:
    """A shortest path start -> ... -> start inside a strongly connected component."""
    previous: dict[str, str] = {}
    frontier = [start]
    while frontier:
        following = []
        for v in frontier:
            for w in deps.get(v, ()):
                if w not in component:
                    continue
                if w == start:
                    path = [v]
                    while path[-1] != start:
                        path.append(previous[path[-1]])
                    return [*reversed(path), start]
                if w not in previous:
                    previous[w] = v
                    following.append(w)
        frontier = following
    return [start, start]


def topological(nodes: list[str], deps: Mapping[str, list[str]], broken: set[str]) -> list[str]:
    """The nodes not on a cycle, each after those it depends on, otherwise as declared."""
    placed: set[str] = set()
    order: list[str] = []
    remaining = [n for n in nodes if n not in broken]
    while remaining:
        for n in remaining:
            if all(d in placed or d in broken for d in deps.get(n, ())):
                break
        else:  # only reachable through a broken node's descendants: keep the written order
            n = remaining[0]
        placed.add(n)
        order.append(n)
        remaining.remove(n)
    return order


def parameters_read(
    name: str, deps: Mapping[str, list[str]], own: Mapping[str, Any]
) -> tuple[str, ...]:
    """The parameters a declaration's expression reads, directly or through derived ones."""
    found: list[str] = []
    seen: set[str] = set()
    stack = list(deps.get(name, ()))
    while stack:
        d = stack.pop()
        if d in seen:
            continue
        seen.add(d)
        if isinstance(own[d], ast.Let):
            stack.extend(deps.get(d, ()))
        else:
            found.append(d)
    return tuple(sorted(found))
