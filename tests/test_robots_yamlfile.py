"""A YAML syntax error names its line and column (nik/robots/yamlfile.py), in a scene file, a robot file and a
dataset's ranges file alike, as one line."""

from __future__ import annotations

import re

import pytest
import yaml

import nik
from nik.errors import RobotDefinitionError
from nik.robots.yamlfile import load_yaml, yaml_problem

#: A flow sequence left unclosed on line 3 (a comma missing, then '}' where ']' was due): the parser stops at the
#: '}' (line 3, column 52), inside the sequence begun at its '[' (column 39).
BAD_SCENE = "# a table and a ball\nboxes:\n  - {center: [0.4, 0.0, -0.05], size: [1.2, 1.2 0.1}\n"


def _place(text: str, needle: str) -> tuple[int, int]:
    """1-based (line, column) of the first ``needle`` in ``text``: the independent count the message must match."""
    for i, line in enumerate(text.splitlines(), start=1):
        if needle in line:
            return i, line.index(needle) + 1
    raise AssertionError(needle)


def test_a_scene_file_with_a_syntax_error_names_line_and_column(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text(BAD_SCENE)
    with pytest.raises(ValueError) as err:
        nik.World.from_file(path)
    message = str(err.value)
    line, column = _place(BAD_SCENE, "}")
    assert message.startswith(f"scene file {path}: not valid YAML: line {line}, column {column}: ")
    assert "expected ',' or ']'" in message  # the parser's words (libyaml: "did not find expected ...")
    began = _place(BAD_SCENE, "[1.2")
    assert f"while parsing a flow sequence begun at line {began[0]}, column {began[1]}" in message
    assert "\n" not in message


def test_a_robot_file_with_a_syntax_error_names_line_and_column(tmp_path):
    text = "name: arm\nconvention: dh\njoints:\n  - {alpha: 0, a: 1, d: 0\n  - {alpha: 0, a: 1, d: 0}\n"
    path = tmp_path / "arm.yaml"
    path.write_text(text)
    with pytest.raises(RobotDefinitionError) as err:
        nik.load_robot(path)
    message = str(err.value)
    assert re.match(rf"{re.escape(str(path))}: not valid YAML: line (\d+), column (\d+): ", message), message
    line, column = map(int, re.search(r"line (\d+), column (\d+)", message).groups())
    mark = _yaml_mark(text)
    assert (line, column) == (mark.line + 1, mark.column + 1) and line == 5  # the next item where '}' was due
    assert "while parsing a flow mapping begun at line 4, column 5" in message and "\n" not in message


def _yaml_mark(text: str):
    try:
        yaml.safe_load(text)
    except yaml.MarkedYAMLError as err:
        return err.problem_mark
    raise AssertionError("valid YAML")


def test_a_ranges_file_with_a_syntax_error_names_line_and_column(tmp_path):
    from nik.data.generate import resolve_ranges

    path = tmp_path / "ranges.yaml"
    path.write_text("angles: deg\nranges: [[-90, 90], [-90 90]]\n  bad: indent\n")
    with pytest.raises(ValueError, match=rf"{re.escape(str(path))}: not valid YAML: line \d+, column \d+: "):
        resolve_ranges(nik.load_robot("puma560"), path)


def test_an_error_without_a_place_gives_its_first_line_and_valid_text_loads():
    assert yaml_problem(yaml.YAMLError("something odd\nmore")) == "something odd"
    assert load_yaml("a: [1, 2]\n", "x.yaml") == {"a": [1, 2]}


def test_a_file_is_parsed_again_only_when_it_changes_and_each_caller_gets_its_own_copy(tmp_path):
    from nik.robots.yamlfile import load_yaml_file

    path = tmp_path / "a.yaml"
    path.write_text("joints: [1, 2]\n")
    first = load_yaml_file(path)
    first["joints"].append(3)  # a caller's change stays its own
    assert load_yaml_file(path) == {"joints": [1, 2]}
    path.write_text("joints: [1, 2, 3, 4]\n")  # another size: read again
    assert load_yaml_file(path) == {"joints": [1, 2, 3, 4]}
    path.write_text("joints: [\n")
    with pytest.raises(ValueError, match=r"not valid YAML: line 2, column 1: "):
        load_yaml_file(path)
