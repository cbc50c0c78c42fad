"""Where in a YAML document a typed load fails: the path of the offending key.

yaml_load_typed's messages name the field at best, never its path. We find the path by
loading ever smaller pieces of the document: a piece keeps one branch of the YAML tree (tags
such as !Rpy intact), and the deepest branch that still fails alone is the culprit.
"""

from __future__ import annotations

import yaml
from pydrake.common.yaml import yaml_load_typed


def locate_bad_key(text: str, schema: type) -> str:
    """The dotted path (e.g. ``gripper_start.height``, ``actions[1][0]``) of the key that
    makes ``yaml_load_typed`` of YAML ``text`` into the dataclass ``schema`` fail;
    ``<yaml line N>`` when the text is not YAML, ``<root>`` when no key is to blame."""
    try:
        root = yaml.compose(text, Loader=yaml.SafeLoader)
    except yaml.YAMLError as error:
        mark = getattr(error, "problem_mark", None)
        return f"<yaml line {mark.line + 1}>" if mark is not None else "<yaml>"
    if not isinstance(root, yaml.MappingNode):
        return "<root>"
    path: list[str] = []

    def fails(wrapped: yaml.Node) -> bool:
        try:
            yaml_load_typed(schema=schema, data=yaml.serialize(wrapped))
        except Exception:
            return True
        return False

    def wrap(chain: list[tuple[yaml.Node, object]], leaf: yaml.Node) -> yaml.Node:
        # Rebuild the document holding only `leaf` at the end of the chain of parents.
        node = leaf
        for parent, key in reversed(chain):
            if isinstance(parent, yaml.MappingNode):
                node = yaml.MappingNode(parent.tag, [(key, node)], flow_style=False)
            else:
                node = yaml.SequenceNode(parent.tag, [node], flow_style=False)
        return node

    chain: list[tuple[yaml.Node, object]] = []
    node: yaml.Node = root
    while True:
        if chain and fails(wrap(chain, _emptied(node))):
            break  # the key itself is at fault (unknown, or of the wrong kind), not its content
        children = _children(node)
        found = None
        for label, key, child in children:
            if fails(wrap([*chain, (node, key)], child)):
                found = (label, key, child)
                break
        if found is None:
            break
        label, key, child = found
        path.append(label)
        chain.append((node, key))
        node = child
    return _format_path(path) or "<root>"


def _emptied(node: yaml.Node) -> yaml.Node:
    """``node`` without its children (a scalar as it is)."""
    if isinstance(node, yaml.MappingNode):
        return yaml.MappingNode(node.tag, [], flow_style=True)
    if isinstance(node, yaml.SequenceNode):
        return yaml.SequenceNode(node.tag, [], flow_style=True)
    return node


def _children(node: yaml.Node) -> list[tuple[str, object, yaml.Node]]:
    """(path label, key node or None, child) of each child of a mapping or sequence."""
    if isinstance(node, yaml.MappingNode):
        return [(str(k.value), k, v) for k, v in node.value]
    if isinstance(node, yaml.SequenceNode):
        return [(f"[{i}]", None, v) for i, v in enumerate(node.value)]
    return []


def _format_path(parts: list[str]) -> str:
    """Path labels joined: ``a.b[0].c``."""
    out = ""
    for part in parts:
        out += part if part.startswith("[") or not out else f".{part}"
    return out
