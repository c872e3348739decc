"""Strict YAML reading: safe_load semantics without duplicate keys or alias bombs, with the line of every key."""
from __future__ import annotations

from typing import Any

import yaml

ALIAS_BUDGET = 10_000  # YAML nodes that aliases may add in total once expanded


class YAMLRefused(yaml.MarkedYAMLError):
    """Valid YAML that a pipeline file may not contain (its message says what to do instead)."""


class StrictLoader(yaml.SafeLoader):
    """``yaml.SafeLoader`` that refuses duplicate keys, recursive aliases and aliases that expand to more than
    ALIAS_BUDGET nodes (a 1 KB "billion laughs" file would otherwise expand to gigabytes)."""

    def __init__(self, stream):
        super().__init__(stream)
        self._open_anchors: set[str] = set()
        self._alias_nodes = 0
        self._sizes: dict[int, int] = {}

    def compose_node(self, parent, index):
        if self.check_event(yaml.AliasEvent):
            event = self.peek_event()
            if event.anchor in self._open_anchors:
                raise YAMLRefused(
                    None, None, f"alias *{event.anchor} refers to a node that contains it (a recursive structure)",
                    event.start_mark)
            if event.anchor in self.anchors:
                self._alias_nodes += self._size(self.anchors[event.anchor])
                if self._alias_nodes > ALIAS_BUDGET:
                    raise YAMLRefused(
                        None, None, f"aliases expand to more than {ALIAS_BUDGET} values; write the values out or use "
                        "${...} references instead of nested aliases", event.start_mark)
            return super().compose_node(parent, index)
        event = self.peek_event()
        anchor = getattr(event, "anchor", None)
        if anchor is not None:
            self._open_anchors.add(anchor)
        try:
            return super().compose_node(parent, index)
        finally:
            self._open_anchors.discard(anchor)

    def _size(self, node) -> int:
        """Number of nodes of ``node`` with aliases expanded (memoized per node)."""
        if id(node) not in self._sizes:
            if isinstance(node, yaml.MappingNode):
                n = 1 + sum(self._size(k) + self._size(v) for k, v in node.value)
            elif isinstance(node, yaml.SequenceNode):
                n = 1 + sum(self._size(v) for v in node.value)
            else:
                n = 1
            self._sizes[id(node)] = n
        return self._sizes[id(node)]

    def construct_mapping(self, node, deep=False):
        if isinstance(node, yaml.MappingNode):
            first: dict = {}
            for key_node, _ in node.value:
                if key_node.tag == "tag:yaml.org,2002:merge" or not isinstance(key_node, yaml.ScalarNode):
                    continue
                key = self.construct_object(key_node)
                if key in first:
                    raise YAMLRefused(
                        None, None, f"duplicate key '{key}' (first at line {first[key].line + 1}, again at line "
                        f"{key_node.start_mark.line + 1}); keep one of them", key_node.start_mark)
                first[key] = key_node.start_mark
        return super().construct_mapping(node, deep=deep)


def parse_yaml(text: str) -> tuple[Any, "KeyLines"]:
    """(the document's value, the line numbers of its keys); raises yaml.YAMLError (see StrictLoader)."""
    loader = StrictLoader(text)
    try:
        node = loader.get_single_node()
        value = loader.construct_document(node) if node is not None else None
    finally:
        loader.dispose()
    return value, KeyLines(node)


class KeyLines:
    """Line numbers of keys in a YAML document: ``lines[("stages","mrf","params")] -> 12``."""

    def __init__(self, node):
        self.lines: dict[tuple, int] = {}
        if node is not None:
            self._walk(node, ())

    def _walk(self, node, path):
        if isinstance(node, yaml.MappingNode):
            for k, v in node.value:
                key = path + (k.value,)
                self.lines[key] = k.start_mark.line + 1
                self._walk(v, key)
        elif isinstance(node, yaml.SequenceNode):
            for i, v in enumerate(node.value):
                self._walk(v, path + (i,))

    def get(self, *path) -> int | None:
        while path:
            if path in self.lines:
                return self.lines[path]
            path = path[:-1]
        return None
