"""The scenario loader under random documents: built from the scenario's own key tree with values
mutated (types, signs, non-finite and huge numbers, exponent forms, deletions, unknown keys,
nesting, duplicate keys in the text), every document gives a valid scenario or a ScenarioError
whose every line names a key path or a line; never another exception.

In the suite a bounded number of examples runs; a long campaign:

    python tests/test_loader_fuzz.py [--examples 100000] [--seed 0]
"""

import argparse
import math
import sys
from pathlib import Path

import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from spotsim import ScenarioError
from spotsim.scenario import from_dict, parse_yaml

ROOT = Path(__file__).resolve().parents[1]
BASES = [yaml.safe_load(p.read_text()) for p in sorted((ROOT / "config").glob("*.yaml"))]

#: Values a key may be given instead of its own.
VALUES = st.one_of(
    st.none(), st.booleans(),
    st.integers(min_value=-(10 ** 400), max_value=10 ** 400),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0, -1, 1e-300, 1e300, -0.0, 1e-9, 2.5e-6]),
    st.text(max_size=20),
    st.sampled_from(["1e-6", "2e0", "-3E2", ".inf", "nan", "", "0x10", "1:2"]),
    st.lists(st.floats(allow_nan=True, allow_infinity=True), max_size=4),
    st.lists(st.integers(), max_size=4),
    st.dictionaries(st.text(max_size=8), st.integers(), max_size=3),
    st.recursive(st.integers(), lambda inner: st.lists(inner, max_size=3), max_leaves=8),
)


def paths(tree, prefix=()):
    """Every key path of a nested mapping (lists' items included), leaves and inner nodes."""
    out = [prefix] if prefix else []
    if isinstance(tree, dict):
        for k, v in tree.items():
            out += paths(v, (*prefix, k))
    elif isinstance(tree, list):
        for i, v in enumerate(tree):
            out += paths(v, (*prefix, i))
    return out


def _parent(tree, path):
    node = tree
    for p in path[:-1]:
        node = node[p]
    return node


@st.composite
def documents(draw):
    """A shipped config with up to six mutations: a value replaced, a key deleted, an unknown key
    added, a value nested in a list or mapping."""
    doc = yaml.safe_load(yaml.safe_dump(draw(st.sampled_from(BASES))))
    for _ in range(draw(st.integers(0, 6))):
        where = paths(doc)
        if not where:
            break
        path = draw(st.sampled_from(where))
        parent = _parent(doc, path)
        action = draw(st.sampled_from(["value", "delete", "unknown", "nest"]))
        if action == "value":
            parent[path[-1]] = draw(VALUES)
        elif action == "delete" and isinstance(parent, dict):
            del parent[path[-1]]
        elif action == "unknown" and isinstance(parent, dict):
            parent[draw(st.text(min_size=1, max_size=8))] = draw(VALUES)
        elif action == "nest":
            parent[path[-1]] = draw(st.sampled_from([[parent[path[-1]]], {"x": parent[path[-1]]}]))
    return doc


def check(doc, text: bool, duplicate: bool) -> str:
    """Load doc (as YAML text when `text`, a top-level key written twice when `duplicate`):
    'valid' or 'invalid'; raises AssertionError on anything else."""
    where = "<fuzz>"
    try:
        if text:
            body = yaml.safe_dump(doc, sort_keys=False, width=10 ** 6)
            if duplicate and isinstance(doc, dict) and doc:
                key = next(iter(doc))
                body += yaml.safe_dump({key: doc[key]}, width=10 ** 6)
            doc = parse_yaml(body, where)
        from_dict(doc if doc is not None else {}, where)
        return "valid"
    except ScenarioError as e:
        assert e.problems, "a ScenarioError with no problem"
        for line in e.problems:
            assert line.startswith(f"{where}: "), line
            rest = line[len(where) + 2:]
            assert " = " in rest or rest.startswith("line ") or ": " in rest, line
        return "invalid"


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(documents(), st.booleans(), st.booleans())
def test_the_loader_gives_a_scenario_or_errors_that_name_a_key_or_a_line(doc, text, duplicate):
    check(doc, text, duplicate)


def test_huge_and_non_finite_numbers_are_errors_not_exceptions():
    """Numbers the schema cannot hold (10^400, inf, nan) are each a key's error."""
    doc = yaml.safe_load(yaml.safe_dump(BASES[0]))
    for value in (10 ** 400, -(10 ** 400), math.inf, math.nan):
        doc["simulation"]["duration_s"] = value
        try:
            from_dict(doc, "<x>")
        except ScenarioError as e:
            assert any(line.startswith("<x>: simulation.duration_s = ") for line in e.problems), e.problems
        else:
            raise AssertionError(f"{value} accepted")


def campaign(examples: int, seed: int) -> None:
    """Run `examples` documents through the loader: counts of valid and invalid, and the first
    failure (an exception other than ScenarioError, or a problem naming no key or line)."""
    import random

    counts = {"valid": 0, "invalid": 0}

    @settings(max_examples=examples, deadline=None, database=None, derandomize=False,
              suppress_health_check=list(HealthCheck))
    @given(documents(), st.booleans(), st.booleans())
    def run(doc, text, duplicate):
        counts[check(doc, text, duplicate)] += 1

    random.seed(seed)
    run()
    total = sum(counts.values())
    print(f"{total} documents: {counts['valid']} valid, {counts['invalid']} refused with a key path or a line; "
          "no other outcome")


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--examples", type=int, default=100_000)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    campaign(args.examples, args.seed)
    sys.exit(0)
