"""Build of LavenderSim's compiled backend, `lavendersim._lavender_c` (metadata lives in pyproject.toml).

The extension is the generated C kernels (generated/kernels.c) plus the hand-written stepping loop and
CPython glue (lavendersim/csrc/*.c). The sha256 of the generated C sources (HASHED) is embedded as
`_lavender_c.GENERATED_HASH`, so importing lavendersim.backends.c_backend can tell a stale build.

    pip install -e .                  # editable install; builds the extension in place
    LAVENDERSIM_BUILD_C=0 pip install -e .   # explicit opt-out: NumPy backend only, no compiler needed
    LAVENDERSIM_NATIVE=1 pip install -e .    # add -march=native (not portable; see the measurements)
    LAVENDERSIM_SANITIZE=1 pip install --target DIR .  # AddressSanitizer + UBSan build, for testing only
        (-O1 -g; run Python with LD_PRELOAD=$(gcc -print-file-name=libasan.so); .ci/sanitize does it all)
    LAVENDERSIM_BUILD_CACHE=DIR pip install -e .   # where compiled extensions are cached (default
        ~/.cache/lavendersim/build, or $XDG_CACHE_HOME/lavendersim/build); LAVENDERSIM_BUILD_CACHE=0: no cache

The build cache: every `pip install -e '.[extra]'` runs this build again. A build whose inputs are the same -
every C source and header it compiles, the flags and macros, the compiler's `--version`, the Python ABI and
platform - reuses the extension compiled the first time instead of compiling for minutes again.

A missing or failing C compiler stops the build with an explanation; it is never skipped silently.
"""
from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import sys
import sysconfig
import tempfile
from pathlib import Path

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext

HERE = Path(__file__).resolve().parent
GENERATED = "generated"
CSRC = "lavendersim/csrc"
HASHED = ("kernels.c", "kernels.h", "layout.h", "tableaux.h", "kernels_f32.c", "kernels_f32.h")


def generated_hash(gen_dir: Path) -> str:
    """sha256 over the per-file sha256 of the generated C sources (HASHED).

    Mirrors lavendersim.backends.c_backend.generated_hash; keep the two identical."""
    h = hashlib.sha256()
    for name in HASHED:
        h.update(f"{name} {hashlib.sha256((gen_dir / name).read_bytes()).hexdigest()}\n".encode())
    return h.hexdigest()


def _flag(name: str) -> bool:
    return os.environ.get(name, "").strip().lower() in ("1", "true", "yes", "on")


class BuildExt(build_ext):
    """build_ext that turns compiler problems into a clear, fatal error."""

    def run(self):
        try:
            super().run()
        except Exception as exc:  # noqa: BLE001 - re-raised with context, never swallowed
            raise SystemExit(_explain(exc)) from exc

    def build_extension(self, ext):
        target = Path(self.get_ext_fullpath(ext.name))
        cache = cache_dir()
        key = cache_key(ext, self.compiler.compiler_so) if cache is not None else None
        if key is not None and cache_fetch(cache, key, target):
            print(f"lavendersim._lavender_c: reusing the build cached as {key[:16]} in {cache}", file=sys.stderr)
            return
        try:
            super().build_extension(ext)
        except Exception as exc:  # noqa: BLE001 - re-raised with context, never swallowed
            raise SystemExit(_explain(exc)) from exc
        if key is not None:
            cache_store(cache, key, target)


def cache_dir() -> Path | None:
    """The build cache's folder (LAVENDERSIM_BUILD_CACHE, else $XDG_CACHE_HOME or ~/.cache, /lavendersim/build),
    or None when LAVENDERSIM_BUILD_CACHE is 0/off/false/no."""
    env = os.environ.get("LAVENDERSIM_BUILD_CACHE", "").strip()
    if env.lower() in ("0", "off", "false", "no"):
        return None
    if env:
        return Path(env).expanduser()
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "lavendersim" / "build"


def _compiler_identity(compiler_so) -> str:
    """The compiler command and its `--version` output ('' when it cannot be run: the build then fails anyway)."""
    cmd = list(compiler_so or [])
    if not cmd:
        return ""
    try:
        out = subprocess.run([cmd[0], "--version"], capture_output=True, text=True, timeout=60).stdout
    except (OSError, subprocess.SubprocessError) as exc:
        out = f"unavailable: {exc}"
    return " ".join(cmd) + "\n" + out


def cache_key(ext, compiler_so) -> str:
    """sha256 over everything the compiled extension depends on: the contents of its sources and of every header
    beside them (csrc/, generated/), its flags and macros, the compiler and its version, Python's ABI and platform."""
    h = hashlib.sha256()
    files = set(map(Path, ext.sources)) | set(map(Path, ext.depends))
    for d in ext.include_dirs:
        files |= set(Path(d).glob("*.h")) | set(Path(d).glob("*.c"))
    for f in sorted(files, key=str):
        p = f if f.is_absolute() else HERE / f
        h.update(f"{f.as_posix()} {hashlib.sha256(p.read_bytes()).hexdigest()}\n".encode())
    for part in (ext.name, ext.extra_compile_args, ext.extra_link_args, ext.define_macros, ext.include_dirs,
                 _compiler_identity(compiler_so), sys.version, sysconfig.get_platform(),
                 sysconfig.get_config_var("EXT_SUFFIX"), sysconfig.get_config_var("CFLAGS")):
        h.update(repr(part).encode() + b"\n")
    return h.hexdigest()


def cache_fetch(cache: Path, key: str, target: Path) -> bool:
    """Copy the cached extension `key` to `target`; False when there is none (or it cannot be read)."""
    src = cache / f"{key}{target.suffix}"
    if not src.is_file():
        return False
    target.parent.mkdir(parents=True, exist_ok=True)
    # a fresh mtime, not the cache entry's (copy2 kept it): setuptools copies the build into the checkout (editable
    # installs) only when it is newer than the file there, so an older cache entry left a stale extension in place
    shutil.copyfile(src, target)
    shutil.copymode(src, target)
    return True


def cache_store(cache: Path, key: str, target: Path) -> None:
    """Keep a copy of the freshly built `target` under `key` (written to a temporary name, then renamed, so a
    concurrent install never reads half a file). A cache that cannot be written is only reported."""
    try:
        cache.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=cache, suffix=".part")
        os.close(fd)
        shutil.copy2(target, tmp)
        os.replace(tmp, cache / f"{key}{target.suffix}")
    except OSError as exc:
        print(f"lavendersim._lavender_c: not cached ({cache}: {exc})", file=sys.stderr)


def _explain(exc: Exception) -> str:
    return (
        f"\nerror: building LavenderSim's C backend (lavendersim._lavender_c) failed: {exc}\n"
        "It needs a C99 compiler (gcc or clang) and the Python development headers, e.g.\n"
        "  Debian/Ubuntu: apt-get install build-essential python3-dev\n"
        "  macOS: xcode-select --install\n"
        "To install without the C backend (NumPy backend only), set LAVENDERSIM_BUILD_C=0 explicitly.\n"
    )


def extensions() -> list[Extension]:
    if os.environ.get("LAVENDERSIM_BUILD_C", "1").strip().lower() in ("0", "false", "no", "off"):
        print("LAVENDERSIM_BUILD_C=0: not building lavendersim._lavender_c (C backend disabled)", file=sys.stderr)
        return []
    for name in HASHED:
        if not (HERE / GENERATED / name).is_file():
            raise SystemExit(f"error: {GENERATED}/{name} is missing; run `lavendersim derive` first "
                             "(or `python -c \"from pathlib import Path; from derive import codegen; "
                             "codegen.write(Path('generated'))\"` from the repo root)")
    csrc = sorted(p.name for p in (HERE / CSRC).glob("*.c"))
    # never -ffast-math: it breaks isfinite and IEEE rules. -ffp-contract=off: no a*b+c fused into an FMA
    # (GCC's default under -std=c99 already; clang contracts by default), so the SIMD copies of the batched
    # loop (csrc/batch_simd.h, AVX2/AVX-512 chosen at run time) give bitwise the scalar path's results
    args = ["-O3", "-std=c99", "-fno-math-errno", "-ffp-contract=off"]
    # only PyInit_ is exported (PyMODINIT_FUNC); hidden symbols cannot be interposed, so -fPIC code
    # calls and inlines the kernels directly (same effect as -fno-semantic-interposition, older compilers too)
    args.append("-fvisibility=hidden")
    if _flag("LAVENDERSIM_NATIVE"):
        args.append("-march=native")
    link_args = []
    if os.name == "posix":  # csrc/step.c: the SIMD tiles of one call may be split over POSIX threads
        args.append("-pthread")
        link_args.append("-pthread")
    if _flag("LAVENDERSIM_SANITIZE"):  # testing build (.ci/sanitize): memory errors and UB abort the process
        sanitize = ["-fsanitize=address,undefined", "-fno-sanitize-recover=undefined"]
        # -fno-wrapv: Python's CFLAGS carry -fwrapv, which defines signed overflow and so hides it from UBSan
        args = [a for a in args if a != "-O3"] + ["-O1", "-g", "-fno-omit-frame-pointer", "-fno-wrapv"] + sanitize
        link_args = link_args + sanitize
        print(f"LAVENDERSIM_SANITIZE=1: building lavendersim._lavender_c with {' '.join(sanitize)} (not for use)",
              file=sys.stderr)
    return [Extension(
        "lavendersim._lavender_c",
        # generated/kernels.c is #included by step.c (one translation unit, so its kernels inline)
        sources=[f"{CSRC}/{n}" for n in csrc],
        include_dirs=[GENERATED, CSRC],
        depends=[f"{GENERATED}/{n}" for n in HASHED] + [f"{CSRC}/step.h", f"{CSRC}/batch_simd.h", f"{CSRC}/model_simd.h",
                                                                    f"{CSRC}/step_f32.h", f"{CSRC}/fixed_loop.h"],
        define_macros=[("LV_GENERATED_HASH", '"%s"' % generated_hash(HERE / GENERATED))],
        extra_compile_args=args,
        extra_link_args=link_args,
    )]


if __name__ == "__main__":  # setuptools runs this file as __main__; tests import it to check the cache key
    setup(ext_modules=extensions(), cmdclass={"build_ext": BuildExt})
