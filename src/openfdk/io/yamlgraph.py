"""The size of a YAML document, checked before it is composed and before any value is
built.

Two passes, both linear in the file:

1. :func:`scan_events` reads the parser's events (no nodes are made) and stops at the
   first alias beyond :data:`openfdk.io.limits.YAML_ALIASES` or the first node beyond
   :data:`openfdk.io.limits.YAML_NODES`, naming its line. Composing costs about 300
   bytes and a few µs per node, so a file of short numbers (two bytes a node) is
   refused before it would take gigabytes.
2. PyYAML composes the file into a graph of nodes in which an alias (``*name``) is the
   very node of its anchor (``&name``). Whatever walks the values afterwards may visit a
   shared node once per reference, though: a dozen lines of aliases expand to 10¹² nodes
   (an "alias bomb"), and an alias inside its own anchor (``&a [*a]``) to infinitely
   many. :func:`check_graph` walks the graph once (each node once, in file order) and
   refuses a recursive document (naming the entry) and one of more nodes, with every
   alias expanded, than :data:`openfdk.io.limits.YAML_NODES`.
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


def _walk(node, with_paths=False):
    """Walk the graph once, each node once, depth first in file order. Returns (alias
    references, expanded sizes by id, entry path of a recursive alias (with_paths only),
    whether an alias is recursive)."""
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


def may_pass_limits(text) -> bool:
    """Whether ``text`` is long enough to hold more aliases or nodes than the limits
    allow, so that :func:`scan_events` must count them: an alias takes at least 2
    characters (``*a`` and a separator), a node at least half a character (``a:`` is a
    mapping, a key and an empty value)."""
    return len(text) > min(2 * limits.YAML_ALIASES, limits.YAML_NODES // 2)


def scan_events(loader, source, error=ValueError):
    """Count the nodes and alias references of the document ``loader`` (a fresh PyYAML
    loader of the text; disposed of here) from its events and raise ``error`` at the
    first beyond :data:`openfdk.io.limits.YAML_ALIASES` or
    :data:`openfdk.io.limits.YAML_NODES` (``<source>: line L: … (counted up to here),
    above the limit of …``). Malformed YAML raises ``yaml.YAMLError``."""
    nodes = aliases = 0
    node_events = (yaml.ScalarEvent, yaml.SequenceStartEvent, yaml.MappingStartEvent)
    try:
        while loader.check_event():
            event = loader.get_event()
            if isinstance(event, yaml.AliasEvent):
                aliases += 1
                if aliases > limits.YAML_ALIASES:
                    limits.check_count(aliases, "YAML_ALIASES", source, f"line {event.start_mark.line + 1}",
                                       "aliases (counted up to here)", error)
            elif isinstance(event, node_events):
                nodes += 1
                if nodes > limits.YAML_NODES:
                    limits.check_count(nodes, "YAML_NODES", source, f"line {event.start_mark.line + 1}",
                                       "YAML nodes (counted up to here)", error)
    finally:
        loader.dispose()
    return nodes, aliases


def check_graph(node, source, error=ValueError):
    """Raise ``error`` (one line naming ``source``) when the composed document ``node``
    is recursive (an alias inside its own anchor, naming the entry) or expands to more
    than :data:`openfdk.io.limits.YAML_NODES` nodes (``<source>: N YAML nodes with the
    aliases expanded (most under <key>), above the limit of …``). Returns the expanded
    node count. The entry path is worked out only for a message (a second walk)."""
    _aliases, size, _, recursive = _walk(node)
    if recursive:
        path = _walk(node, with_paths=True)[2] or "(top level)"
        raise error(f"{source}: {path}: an alias refers to a node that contains it (the document would be "
                    "infinite when expanded)")
    total = size[id(node)]
    if total > limits.YAML_NODES:
        what = "YAML nodes with the aliases expanded" + (" (or more)" if total >= _CAP else "")
        if isinstance(node, yaml.MappingNode) and node.value:
            k, _v = max(node.value, key=lambda kv: size[id(kv[1])])
            what += f" (most under {_key_text(k)})"
        limits.check_count(total, "YAML_NODES", source, "", what, error)
    return total
