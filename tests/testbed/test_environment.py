"""The environment record of an evaluation (library versions, GL renderer)."""

import numpy as np

from markerplace.errors import UserError
from markerplace.testbed import environment as env


def test_environment_names_versions_and_renderer():
    got = env.environment()
    assert set(got["packages"]) == set(env.PACKAGES)
    assert got["packages"]["numpy"] == np.__version__ and got["packages"]["markerplace"]
    assert got["python"].count(".") == 2
    assert "GL_RENDERER" in got["gl"] and got["gl"]["GL_VERSION"] != "?"
    assert "gl" not in env.environment(gl=False)


def test_gl_info_says_why_when_there_is_no_context(monkeypatch):
    def broken():
        raise UserError("cannot create an OpenGL context on EGL (no driver)")

    monkeypatch.setattr(env, "create_context", broken)  # the function gl_info calls
    assert env.gl_info() == {"error": "cannot create an OpenGL context on EGL (no driver)"}
