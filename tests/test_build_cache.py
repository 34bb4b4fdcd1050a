"""The C build cache in setup.py: a second install with the same inputs reuses the compiled extension, and any
change to what the extension is built from (a source byte, a header beside it, a flag) misses the cache."""
from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import pytest
from setuptools import Extension

ROOT = Path(__file__).resolve().parents[1]


def _setup_module():
    spec = importlib.util.spec_from_file_location("lavendersim_setup_under_test", ROOT / "setup.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)  # setup() itself runs only as __main__
    return mod


@pytest.fixture()
def S():
    return _setup_module()


def _ext(tmp_path, flags=("-O3",)):
    src = tmp_path / "src"
    src.mkdir(exist_ok=True)
    if not (src / "a.c").exists():
        (src / "a.c").write_text("int a(void) { return 1; }\n")
        (src / "b.h").write_text("#define B 2\n")
    return Extension("pkg._x", sources=[str(src / "a.c")], include_dirs=[str(src)], extra_compile_args=list(flags))


def test_key_is_stable_and_sees_every_input(S, tmp_path):
    cc = ["gcc", "-pthread"]
    k0 = S.cache_key(_ext(tmp_path), cc)
    assert S.cache_key(_ext(tmp_path), cc) == k0
    (tmp_path / "src" / "b.h").write_text("#define B 3\n")  # a header beside the sources, not listed anywhere
    k1 = S.cache_key(_ext(tmp_path), cc)
    assert k1 != k0
    (tmp_path / "src" / "a.c").write_text("int a(void) { return 2; }\n")
    k2 = S.cache_key(_ext(tmp_path), cc)
    assert k2 != k1
    assert S.cache_key(_ext(tmp_path, ("-O3", "-march=native")), cc) != k2
    assert S.cache_key(_ext(tmp_path), ["clang"]) != k2


def test_the_real_extension_has_a_key(S):
    (ext,) = S.extensions()
    key = S.cache_key(ext, ["gcc"])
    assert len(key) == 64 and int(key, 16) >= 0


def test_fetch_store_round_trip(S, tmp_path):
    built = tmp_path / "build" / "_x.so"
    built.parent.mkdir()
    built.write_bytes(b"\x7fELF compiled")
    cache = tmp_path / "cache"
    out = tmp_path / "out" / "_x.so"
    assert not S.cache_fetch(cache, "k" * 64, out)
    S.cache_store(cache, "k" * 64, built)
    assert [p.name for p in cache.iterdir()] == ["k" * 64 + ".so"]  # no temporary file left behind
    assert S.cache_fetch(cache, "k" * 64, out)
    assert out.read_bytes() == b"\x7fELF compiled"


def test_a_fetched_build_is_newer_than_the_one_in_the_checkout(S, tmp_path):
    """setuptools copies an editable install's extension into the checkout only when it is newer than the file there
    (distutils copy_file's update): a fetch keeping the cache entry's old mtime left a stale extension in the clone
    after a pull and a second `pip install -e .` (StaleBuildError in every C test of the lead's clean-clone run)."""
    import os

    built = tmp_path / "_x.so"
    built.write_bytes(b"\x7fELF old sources")
    cache = tmp_path / "cache"
    S.cache_store(cache, "o" * 64, built)
    os.utime(cache / ("o" * 64 + ".so"), (1_000_000_000, 1_000_000_000))      # an entry stored long ago
    in_checkout = tmp_path / "checkout.so"
    in_checkout.write_bytes(b"\x7fELF newer sources, installed since")
    out = tmp_path / "out" / "_x.so"
    assert S.cache_fetch(cache, "o" * 64, out)
    assert out.stat().st_mtime >= in_checkout.stat().st_mtime


def test_cache_dir_from_environment(S, tmp_path, monkeypatch):
    monkeypatch.setenv("LAVENDERSIM_BUILD_CACHE", str(tmp_path / "c"))
    assert S.cache_dir() == tmp_path / "c"
    for off in ("0", "off", "no", "false"):
        monkeypatch.setenv("LAVENDERSIM_BUILD_CACHE", off)
        assert S.cache_dir() is None
    monkeypatch.delenv("LAVENDERSIM_BUILD_CACHE")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert S.cache_dir() == tmp_path / "xdg" / "lavendersim" / "build"


def test_unwritable_cache_is_reported_not_fatal(S, tmp_path, capsys):
    built = tmp_path / "_x.so"
    built.write_bytes(b"x")
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    S.cache_store(blocker / "cache", "k" * 64, built)
    assert "not cached" in capsys.readouterr().err


@pytest.mark.slow
def test_second_build_reuses_the_first(tmp_path):
    """Two wheel builds of the real extension from the same sources (pip's isolated build, as an install does):
    the second reports the reuse and carries bitwise the first's extension (compiles once: a few minutes)."""
    import zipfile

    env = dict(os.environ, LAVENDERSIM_BUILD_CACHE=str(tmp_path / "cache"))
    outs, sos = [], []
    for i in range(2):
        run = subprocess.run([sys.executable, "-m", "pip", "wheel", "-v", "--no-deps", "-w", str(tmp_path / f"w{i}"),
                              str(ROOT)], env=env, capture_output=True, text=True, timeout=3600)
        assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-2000:]
        outs.append(run.stdout + run.stderr)
        (wheel,) = (tmp_path / f"w{i}").glob("*.whl")
        with zipfile.ZipFile(wheel) as z:
            (name,) = [n for n in z.namelist() if n.startswith("lavendersim/_lavender_c")]
            sos.append(z.read(name))
    assert "reusing the build cached" not in outs[0]
    assert "reusing the build cached" in outs[1]
    assert sos[0] == sos[1]
    assert len([p for p in (tmp_path / "cache").iterdir() if p.suffix == ".so"]) == 1
