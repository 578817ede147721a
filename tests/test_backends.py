"""How long jobs run (garage_mj.core.backends.Compute): a bad value is one clear error, before any job."""

from __future__ import annotations

import dataclasses

import pytest

from garage_mj.cli import main
from garage_mj.core.backends import BackendError, Compute, map_unordered


@pytest.mark.parametrize(("kwargs", "message"), [
    ({"workers": 0}, "workers must be >= 1, got 0"),
    ({"workers": True}, "workers must be >= 1, got True"),
    ({"workers": "2"}, "workers must be >= 1, got '2'"),
    ({"backend": "dask"}, "unknown backend 'dask'; choose one of local, ray"),
    ({"address": "10.0.0.1:6379"}, "--address names a Ray cluster; use it with --backend ray"),
    ({"progress": "yes"}, "progress must be True or False, got 'yes'"),
])
def test_a_bad_compute_value_is_one_clear_error(kwargs, message):
    with pytest.raises(BackendError) as err:
        Compute(**kwargs)
    assert str(err.value) == message  # one line, naming the value and the fix
    with pytest.raises(BackendError):  # a changed copy is checked too
        dataclasses.replace(Compute(), **kwargs)


def test_compute_defaults_and_a_local_batch():
    assert Compute() == Compute(workers=1, backend="local", address=None, progress=True)
    assert sorted(map_unordered(abs, [-2, 1, -3], compute=Compute(progress=False))) == [1, 2, 3]
    assert list(map_unordered(abs, [])) == []


def test_the_command_line_says_a_bad_address_in_one_line(capsys):
    assert main(["hunt", "--map", "tiny_7x11", "--address", "10.0.0.1:6379", "--out", "/nonexistent/x"]) == 2
    err = capsys.readouterr().err
    assert err == "garage-mj hunt: error: --address names a Ray cluster; use it with --backend ray\n"
