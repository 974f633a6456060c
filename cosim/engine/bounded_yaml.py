"""The one YAML reader of the platform: ``yaml.safe_load`` bounded against documents whose aliases expand to more
values than any real file holds (a "billion laughs": 1 KB that expands to gigabytes). Scenarios, their overrides,
scenarios attached to logs and identified model files all go through :func:`load_yaml`."""

from __future__ import annotations

import sys
from typing import Any

import yaml

__all__ = ["MAX_YAML_NODES", "YamlTooLarge", "load_yaml"]


MAX_YAML_NODES = 200_000
"""Values a scenario file may expand to, aliases counted at every use (the shipped ones have fewer than 500)."""


def _expanded_nodes(root: yaml.Node) -> int:
    """How many values ``root`` holds with every alias expanded, counted up to just past :data:`MAX_YAML_NODES`
    (a composed graph shares aliased nodes, so nine levels of nine aliases are a few hundred nodes that expand
    to 387 million values)."""
    count, stack = 0, [root]
    while stack and count <= MAX_YAML_NODES:
        node = stack.pop()
        count += 1
        if isinstance(node, yaml.MappingNode):
            stack.extend(v for pair in node.value for v in pair)
        elif isinstance(node, yaml.SequenceNode):
            stack.extend(node.value)
    return count


class YamlTooLarge(yaml.YAMLError):
    """YAML whose aliases expand past :data:`MAX_YAML_NODES` values."""


def _duplicate_key(root: yaml.Node) -> yaml.constructor.ConstructorError | None:
    """The first mapping key ``root`` gives twice (YAML forbids it; PyYAML keeps the last silently, so a value
    written twice in a scenario would lose the first without a word), as an error marked at the second."""
    seen_nodes: set[int] = set()
    stack = [root]
    while stack:
        node = stack.pop()
        if id(node) in seen_nodes:  # an alias: checked once
            continue
        seen_nodes.add(id(node))
        if isinstance(node, yaml.MappingNode):
            first: dict[tuple[str, str], yaml.Node] = {}
            for key, value in node.value:
                if isinstance(key, yaml.ScalarNode) and key.tag != "tag:yaml.org,2002:merge":
                    if (key.tag, key.value) in first:
                        line = first[(key.tag, key.value)].start_mark.line + 1
                        return yaml.constructor.ConstructorError(
                            None, None, f"duplicate key {key.value!r} (first given at line {line}): a mapping gives "
                                        "each key once", key.start_mark)
                    first[(key.tag, key.value)] = key
                stack.extend((key, value))
        elif isinstance(node, yaml.SequenceNode):
            stack.extend(node.value)
    return None


def _unreadable_integer(root: yaml.Node) -> yaml.constructor.ConstructorError | None:
    """The first integer with more digits than Python converts from text (``sys.get_int_max_str_digits``: 4300; a
    longer one raised a ValueError from inside PyYAML, shown as an internal error), as an error marked at it."""
    limit = sys.get_int_max_str_digits()
    seen: set[int] = set()
    stack = [root]
    while stack:
        node = stack.pop()
        if id(node) in seen:
            continue
        seen.add(id(node))
        if isinstance(node, yaml.MappingNode):
            stack.extend(v for pair in node.value for v in pair)
        elif isinstance(node, yaml.SequenceNode):
            stack.extend(node.value)
        elif node.tag == "tag:yaml.org,2002:int" and limit and sum(c.isdigit() for c in node.value) > limit:
            digits = sum(c.isdigit() for c in node.value)
            return yaml.constructor.ConstructorError(
                None, None, f"an integer of {digits:,} digits: more than any value holds (at most {limit:,})",
                node.start_mark)
    return None


def load_yaml(text: str | bytes) -> tuple[Any, yaml.Node | None]:
    """``yaml.safe_load`` of ``text`` that refuses, before building anything, a document whose aliases expand past
    :data:`MAX_YAML_NODES` values (:class:`YamlTooLarge`, a ``yaml.YAMLError``); also returns the composed node
    tree (None for an empty document). A key given twice in a mapping is refused (a ``ConstructorError`` marked at
    the second), where PyYAML keeps the last; an integer too long for Python to convert is refused where it is. Every
    YAML the platform reads from a file, a log or an option goes
    through here."""
    root = yaml.compose(text, Loader=yaml.SafeLoader)
    if root is None:
        return None, None
    if _expanded_nodes(root) > MAX_YAML_NODES:
        # Refused (security): an alias bomb: 1 kB of YAML expanded to 8 GB
        raise YamlTooLarge(f"the YAML expands to more than {MAX_YAML_NODES} values (aliases of aliases nested too "
                           "deep, a 'billion laughs'): refused")
    duplicate = _duplicate_key(root)
    if duplicate is not None:
        # Refused (correctness): a key given twice: PyYAML kept the last silently, which one is meant is a guess
        raise duplicate
    too_long = _unreadable_integer(root)
    if too_long is not None:
        # Refused (security): Python bounds the digits it converts (a quadratic conversion); no value needs more
        raise too_long
    loader = yaml.SafeLoader("")
    try:
        return loader.construct_document(root), root
    finally:
        loader.dispose()
