"""YAML files of ROS (map_server maps, AMCL parameters) read with PyYAML, strictly and with line numbers.

PyYAML's ``safe_load`` keeps the last of two equal keys without a word; ROS
refuses such a file (yaml-cpp, and ``rosparam load``, report the duplicate),
so :func:`load_yaml` refuses it too, naming both lines. Syntax errors become
:class:`~localize.io._common.FormatError` with the line PyYAML points at.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import yaml

from ._common import FormatError

__all__ = ["load_yaml", "load_yaml_mapping"]

PathLike = str | os.PathLike


class _Duplicate(Exception):
    def __init__(self, key: Any, first: int, line: int) -> None:
        super().__init__(key)
        self.key, self.first, self.line = key, first, line


class _StrictLoader(yaml.SafeLoader):
    """PyYAML's safe loader that refuses a key given twice in one mapping."""

    def construct_mapping(self, node, deep=False):
        if isinstance(node, yaml.MappingNode):
            seen: dict[Any, int] = {}
            for key_node, _ in node.value:
                key = self.construct_object(key_node, deep=True)
                try:
                    first = seen.setdefault(key, key_node.start_mark.line + 1)
                except TypeError:  # an unhashable key: PyYAML reports it below
                    continue
                if first != key_node.start_mark.line + 1:
                    raise _Duplicate(key, first, key_node.start_mark.line + 1)
        return super().construct_mapping(node, deep=deep)


def _syntax_error(path: Path, exc: yaml.YAMLError, text: str, what: str | None = None) -> FormatError:
    mark = getattr(exc, "problem_mark", None)
    line = mark.line + 1 if mark is not None else None
    if isinstance(exc, yaml.reader.ReaderError):  # a character YAML does not allow
        line = text[:exc.position].count("\n") + 1
        ch = chr(exc.character) if isinstance(exc.character, int) else exc.character
        return FormatError(path, line, f"not valid YAML: the character {ch!r} is not allowed in YAML text")
    problem = getattr(exc, "problem", None) or exc
    if what is not None:
        return FormatError(path, line, f"not valid YAML ({problem}): expected 'key: value' lines ({what})")
    return FormatError(path, line, f"not valid YAML: {problem}")


def load_yaml(path: PathLike, text: str | None = None) -> Any:
    """The YAML document of ``path`` (PyYAML, safe); a key given twice is a :class:`FormatError`.

    Examples
    --------
    >>> load_yaml(tmp_text("a.yaml", "a: 1\\nb: [2, 3]\\n"))
    {'a': 1, 'b': [2, 3]}
    >>> load_yaml(tmp_text("a.yaml", "amcl:\\n  alpha1: 0.2\\n  alpha1: 0.3\\n"))
    Traceback (most recent call last):
    ...
    localize.io._common.FormatError: ...a.yaml:3: key 'alpha1' appears twice (first on line 2); ROS refuses such a file: keep one
    """
    p = Path(path)
    text = p.read_text(errors="replace") if text is None else text
    try:
        return yaml.load(text, Loader=_StrictLoader)  # noqa: S506 - a SafeLoader subclass
    except _Duplicate as d:
        raise FormatError(p, d.line, f"key {d.key!r} appears twice (first on line {d.first}); ROS refuses such a "
                                     "file: keep one") from None
    except yaml.YAMLError as exc:
        raise _syntax_error(p, exc, text) from None
    except (TypeError, ValueError, RecursionError) as exc:  # e.g. an unhashable key, a date out of range
        raise FormatError(p, None, f"not valid YAML for this file: {exc}") from None


def _plain_number(node: yaml.Node, value: Any) -> Any:
    """``1e-2`` is a number for ROS (yaml-cpp) but a string for PyYAML's YAML 1.1 resolver: read it as one."""
    if isinstance(value, str) and isinstance(node, yaml.ScalarNode) and node.style is None:
        try:
            return float(value)
        except ValueError:
            return value
    return value


def load_yaml_mapping(path: PathLike, text: str, what: str) -> dict[str, tuple[Any, int]]:
    """A flat YAML mapping as ``{key: (value, line)}``; nested values, repeated keys are :class:`FormatError`.

    ``what`` names the kind of file for the messages.

    Examples
    --------
    >>> p = tmp_text("m.yaml", "image: m.pgm  # the picture\\nresolution: 1e-2\\norigin: [-1.0, 2, 0.0]\\n")
    >>> d = load_yaml_mapping(p, p.read_text(), "a map")
    >>> d["image"], d["resolution"], d["origin"]
    (('m.pgm', 1), (0.01, 2), ([-1.0, 2, 0.0], 3))
    """
    p = Path(path)
    loader = None
    try:
        loader = _StrictLoader(text)
        root = loader.get_single_node()
        if root is None or not isinstance(root, yaml.MappingNode):
            line = root.start_mark.line + 1 if root is not None else None
            raise FormatError(p, line, f"expected 'key: value' lines ({what}); got "
                                       f"{'nothing' if root is None else 'a ' + root.id}")
        out: dict[str, tuple[Any, int]] = {}
        for key_node, value_node in root.value:
            line = key_node.start_mark.line + 1
            key = loader.construct_object(key_node, deep=True)
            if not isinstance(key, str):
                raise FormatError(p, line, f"expected 'key: value' with a name as key ({what}); got {key!r}")
            if key in out:
                raise FormatError(p, line, f"key {key!r} appears twice (first on line {out[key][1]})")
            value = loader.construct_object(value_node, deep=True)
            if value is None or isinstance(value, dict):
                raise FormatError(p, line, f"key {key!r} has no value; nested YAML is not {what}")
            if isinstance(value, list):
                value = [_plain_number(n, v) for n, v in zip(value_node.value, value)]
            out[key] = (_plain_number(value_node, value), line)
        return out
    except yaml.YAMLError as exc:
        raise _syntax_error(p, exc, text, what) from None
    except (TypeError, ValueError, RecursionError) as exc:
        if isinstance(exc, FormatError):
            raise
        raise FormatError(p, None, f"not valid YAML for {what}: {exc}") from None
    finally:
        if loader is not None:
            loader.dispose()
