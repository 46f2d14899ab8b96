"""The OBJ reader: groups, materials, polygons, index forms and errors."""

import numpy as np
import pytest

from viscx.errors import ViscxError
from viscx.formats.obj import read_obj


def write(tmp_path, text, name="s.obj"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_groups_materials_and_polygons(tmp_path):
    write(tmp_path, "newmtl white\nKd 0.7 0.7 0.7\nnewmtl lamp\nKd 0.8 0.8 0.8\nKe 17 12 4\n", "s.mtl")
    path = write(
        tmp_path,
        "mtllib s.mtl\n# comment\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvn 0 0 1\n"
        "o floor\nusemtl white\nf 1/1/1 2/1/1 3//1 4\n"
        "g light\nusemtl lamp\nf -4 -3 -2\n"
        "o floor\nf 1 3 4\n",
    )
    soup = read_obj(path)
    assert soup.group_names == ["floor", "light"]
    assert soup.polygon_group.tolist() == [0, 1, 0]
    assert np.diff(soup.polygon_offsets).tolist() == [4, 3, 3]
    assert soup.polygon_vertices[4:7].tolist() == [0, 1, 2]  # negative indices are relative
    assert soup.material_names == ["white", "lamp"]
    assert soup.polygon_material.tolist() == [0, 1, 1]
    assert np.allclose(soup.material_ke[1], [17, 12, 4]) and np.allclose(soup.material_kd[0], 0.7)


def test_faces_before_any_group_go_to_default(tmp_path):
    soup = read_obj(write(tmp_path, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"))
    assert soup.group_names == ["default"]


@pytest.mark.parametrize(
    "text, message",
    [
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n", "out of range"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 0\n", "out of range"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\n", "at least 3"),
        ("v 0 0 zero\n", "expected 3 numbers"),
        ("v 0 0\n", "expected 3 numbers"),
        ("v 0 0 nan\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "NaN or infinite"),
        ("v 0 0 inf\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "NaN or infinite"),
        ("v 0 0 0\nf 1 x 3\n", "bad vertex index"),
    ],
)
def test_errors_name_the_problem_and_line(tmp_path, text, message):
    with pytest.raises(ViscxError, match=message):
        read_obj(write(tmp_path, text))
