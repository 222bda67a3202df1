"""``casflex scene``: a built-in scene written out to edit (issue 48, item 11)."""

from __future__ import annotations

import pytest

from casflex.cli import main
from casflex.scene.io import builtin_scenes, dumps_scene, load_scene


@pytest.mark.parametrize("name", ["twobar", "leg", "hamner_leg"])
def test_scene_show_writes_a_built_in_scene_that_loads_as_the_same_scene(name, tmp_path, capsys, monkeypatch):
    assert main(["scene", "show", name]) == 0
    text = capsys.readouterr().out
    assert text.startswith("#") or "[[nodes]]" in text  # the file as shipped, its comments kept
    path = tmp_path / "my.toml"
    path.write_text(text)
    monkeypatch.chdir(tmp_path)  # loaded away from the package: it names no file of its own folder
    assert dumps_scene(load_scene(str(path))) == dumps_scene(load_scene(name))


def test_scene_list_and_a_name_that_is_no_built_in_scene(capsys):
    assert main(["scene", "list"]) == 0
    assert capsys.readouterr().out.split() == builtin_scenes()
    assert main(["scene", "show", "my_leg"]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err == ("casflex: error: NAME: scene 'my_leg': not a built-in scene (built-in: "
                                 f"{', '.join(builtin_scenes())})\n")
