"""The size of a composed YAML document, checked before any value is built.

PyYAML composes a file into a graph of nodes in which an alias (``*name``) is the very
node of its anchor (``&name``), so composing stays linear in the file's length. Whatever
walks the values afterwards may visit a shared node once per reference, though: a dozen
lines of aliases expand to 10¹² nodes (an "alias bomb"), and an alias inside its own
anchor (``&a [*a]``) to infinitely many. :func:`check_graph` walks the graph once (each
node once, in file order) and refuses, naming the file and the entry:

* more alias references than :data:`openfdk.io.limits.YAML_ALIASES`;
* an alias that refers to a node containing it (a recursive document);
* more nodes, with every alias expanded, than :data:`openfdk.io.limits.YAML_NODES`.
"""

from __future__ import annotations

import yaml

from . import limits

#: expanded sizes saturate here (Python's integers would grow without bound in a bomb)
_CAP = 10**18


def _key_text(node) -> str:
    return str(node.value) if isinstance(node, yaml.ScalarNode) else f"<{node.tag.rsplit(':', 1)[-1]}>"


def _children(node, path):
    """The child nodes of a mapping (keys and values) or sequence node in file order,
    each with its entry path (``path`` None: no paths, None each)."""
    if isinstance(node, yaml.MappingNode):
        if path is None:
            return [(c, None) for kv in node.value for c in kv]
        out = []
        for k, v in node.value:
            here = f"{path}.{_key_text(k)}" if path else _key_text(k)
            out += [(k, here), (v, here)]
        return out
    if path is None:
        return [(c, None) for c in node.value]
    return [(v, f"{path}[{i}]") for i, v in enumerate(node.value)]


def _walk(node, with_paths=False, stop_at_alias=None):
    """Walk the graph once, each node once, depth first in file order. Returns (alias
    references, expanded sizes by id, entry path of the alias number ``stop_at_alias``
    or of a recursive alias (with_paths only), whether an alias is recursive)."""
    size, open_ids, aliases = {}, set(), 0
    stack = [(node, "" if with_paths else None, False)]
    while stack:
        n, path, leaving = stack.pop()
        key = id(n)
        if leaving:
            open_ids.discard(key)
            size[key] = min(_CAP, 1 + sum(size[id(c)] for c, _ in _children(n, None)))
            continue
        if key in size:
            aliases += 1
            if aliases == stop_at_alias:
                return aliases, size, path, False
            continue
        if key in open_ids:
            return aliases, size, path, True
        if isinstance(n, yaml.ScalarNode):
            size[key] = 1
            continue
        open_ids.add(key)
        stack.append((n, path, True))
        stack.extend((c, p, False) for c, p in reversed(_children(n, path)))
    return aliases, size, None, False


def check_graph(node, source, error=ValueError):
    """Raise ``error`` (one line: ``<source>: …, above the limit of … (openfdk.io.limits.
    NAME)``) when the composed document ``node`` has too many aliases, is recursive, or
    expands to too many nodes. Returns the expanded node count. Entry paths are worked
    out only for a message (a second walk)."""
    aliases, size, _, recursive = _walk(node)
    if recursive:
        path = _walk(node, with_paths=True)[2] or "(top level)"
        raise error(f"{source}: {path}: an alias refers to a node that contains it (the document would be "
                    "infinite when expanded)")
    if aliases > limits.YAML_ALIASES:
        first_over = _walk(node, with_paths=True, stop_at_alias=limits.YAML_ALIASES + 1)[2]
        limits.check_count(aliases, "YAML_ALIASES", source, "",
                           f"aliases (alias number {limits.YAML_ALIASES + 1:,} at {first_over})".replace(",", " "),
                           error)
    total = size[id(node)]
    if total > limits.YAML_NODES:
        what = "YAML nodes with the aliases expanded" + (" (or more)" if total >= _CAP else "")
        if isinstance(node, yaml.MappingNode) and node.value:
            k, _v = max(node.value, key=lambda kv: size[id(kv[1])])
            what += f" (most under {_key_text(k)})"
        limits.check_count(total, "YAML_NODES", source, "", what, error)
    return total
