"""The one YAML reader of the platform: ``yaml.safe_load`` bounded against documents whose aliases expand to more
values than any real file holds (a "billion laughs": 1 KB that expands to gigabytes). Scenarios, their overrides,
scenarios attached to logs and identified model files all go through :func:`load_yaml`."""

from __future__ import annotations

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


def load_yaml(text: str | bytes) -> tuple[Any, yaml.Node | None]:
    """``yaml.safe_load`` of ``text`` that refuses, before building anything, a document whose aliases expand past
    :data:`MAX_YAML_NODES` values (:class:`YamlTooLarge`, a ``yaml.YAMLError``); also returns the composed node
    tree (None for an empty document). Every YAML the platform reads from a file, a log or an option goes
    through here."""
    root = yaml.compose(text, Loader=yaml.SafeLoader)
    if root is None:
        return None, None
    if _expanded_nodes(root) > MAX_YAML_NODES:
        raise YamlTooLarge(f"the YAML expands to more than {MAX_YAML_NODES} values (aliases of aliases nested too "
                           "deep, a 'billion laughs'): refused")
    loader = yaml.SafeLoader("")
    try:
        return loader.construct_document(root), root
    finally:
        loader.dispose()
