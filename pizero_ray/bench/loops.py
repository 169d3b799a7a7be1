"""The while loops of a compiled program, read from its HLO text: how they nest and which run a data-dependent
number of times.

On a GPU each trip of a while loop evaluates its condition on the device and copies it to the host before the
next launch (unless XLA captures the loop in a command buffer), so the nest of loops inside one agent step is
what bounds the step's latency there: the episode loop, mctx's loop over simulations, and inside it the
walk down and the backup of each simulation, both data-dependent. Pure text processing: no JAX.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

_COMPUTATION = re.compile(r"^(?:ENTRY\s+)?%([\w.\-]+)\s.*\{\s*$")
_WHILE = re.compile(r"\swhile\(.*condition=%([\w.\-]+).*body=%([\w.\-]+)")
_TRIP = re.compile(r'"known_trip_count":\{"n":"(\d+)"\}')
_CALLED = re.compile(r"(?:calls|to_apply|true_computation|false_computation)=%([\w.\-]+)")
_BRANCHES = re.compile(r"branch_computations=\{([^}]*)\}")
_OPCODE = re.compile(r"=\s.*?\s([a-z][a-z0-9\-]*)\(")
# Instructions that launch nothing: they name, pack or unpack values. A while loop is counted as a loop, and a
# call's or conditional's computations are counted where they run.
_FREE = frozenset({"parameter", "get-tuple-element", "tuple", "constant", "bitcast", "while", "call", "conditional",
                   "after-all", "opt-barrier", "partition-id", "replica-id"})


@dataclass
class Loop:
    """A while loop: its trip count where XLA knows it (None: data-dependent), and the loops inside its body."""

    trip_count: int | None
    inner: list[Loop] = field(default_factory=list)
    # Instructions one trip runs outside the inner loops (condition and body; a fusion counts once): on a GPU
    # about the kernels a trip launches, where the program was compiled for the GPU.
    ops: int = 0

    @property
    def holds_data_dependent(self) -> bool:
        return self.trip_count is None or any(loop.holds_data_dependent for loop in self.inner)


def _computations(hlo_text: str) -> tuple[dict[str, list[str]], str]:
    """Each computation's instruction lines, by name, and the entry computation's name."""
    computations: dict[str, list[str]] = {}
    entry, current = "", None
    for line in hlo_text.splitlines():
        match = _COMPUTATION.match(line)
        if match:
            current = match.group(1)
            computations[current] = []
            entry = current if line.startswith("ENTRY") else entry
        elif line.strip() == "}":
            current = None
        elif current is not None:
            computations[current].append(line)
    return computations, entry


def loop_nest(hlo_text: str) -> list[Loop]:
    """The outermost while loops of the entry computation (through calls, fusions and conditionals), each with
    the loops nested in its condition and body."""
    computations, entry = _computations(hlo_text)

    def loops_in(name: str, seen: frozenset) -> list[Loop]:
        if name in seen or name not in computations:
            return []
        seen, found = seen | {name}, []
        for line in computations[name]:
            loop = _WHILE.search(line)
            if loop:
                trip = _TRIP.search(line)
                found.append(Loop(int(trip.group(1)) if trip else None,
                                  loops_in(loop.group(1), seen) + loops_in(loop.group(2), seen),
                                  ops_in(computations, loop.group(1)) + ops_in(computations, loop.group(2))))
                continue
            called = _CALLED.findall(line)
            for branches in _BRANCHES.findall(line):
                called += [b.strip().lstrip("%") for b in branches.split(",") if b.strip()]
            for callee in called:
                found += loops_in(callee, seen)
        return found

    return loops_in(entry, frozenset())


def ops_in(computations: dict[str, list[str]], name: str, seen: frozenset = frozenset()) -> int:
    """Instructions computation ``name`` runs each time, through calls and conditionals' branches (all of
    them: an upper bound), not into while loops (counted as loops) or fusions (one each)."""
    if name in seen or name not in computations:
        return 0
    seen, count = seen | {name}, 0
    for line in computations[name]:
        opcode = _OPCODE.search(line)
        if opcode is None:
            continue
        if opcode.group(1) not in _FREE:
            count += 1
        elif opcode.group(1) in ("call", "conditional"):
            called = _CALLED.findall(line)
            for branches in _BRANCHES.findall(line):
                called += [b.strip().lstrip("%") for b in branches.split(",") if b.strip()]
            count += sum(ops_in(computations, callee, seen) for callee in called)
    return count


def shape(loops: list[Loop]) -> str:
    """The nest as text, keeping only loops that are, or hold, data-dependent ones: ``?`` a data-dependent
    loop, a number a known trip count, inner loops in brackets. E.g. ``?[10[? ?]]``: an episode loop around
    10 simulations, each a walk down and a backup."""
    kept = [loop for loop in loops if loop.holds_data_dependent]
    return " ".join(("?" if loop.trip_count is None else str(loop.trip_count))
                    + (f"[{shape(loop.inner)}]" if shape(loop.inner) else "") for loop in kept)


def ops_shape(loops: list[Loop]) -> str:
    """``shape`` with each loop's instructions a trip after a colon: ``?:40[10:25[?:9 ?:7]]``."""
    kept = [loop for loop in loops if loop.holds_data_dependent]
    return " ".join(("?" if loop.trip_count is None else str(loop.trip_count)) + f":{loop.ops}"
                    + (f"[{ops_shape(loop.inner)}]" if ops_shape(loop.inner) else "") for loop in kept)


def summary(hlo_text: str) -> dict:
    """What the bench records of a compiled program's loops."""
    loops = loop_nest(hlo_text)

    def walk(nest: list[Loop], depth: int):
        for loop in nest:
            yield loop, depth
            yield from walk(loop.inner, depth + 1)

    every = list(walk(loops, 1))
    return {
        "while_loops": len(every),
        "data_dependent_while_loops": sum(loop.trip_count is None for loop, _ in every),
        "deepest_loop_nest": max((depth for _, depth in every), default=0),
        "data_dependent_loop_shape": shape(loops),
        "ops_per_trip_shape": ops_shape(loops),
        "program_ops": ops_in(_computations(hlo_text)[0], _computations(hlo_text)[1]),
    }
