"""Build of LavenderSim's compiled backend, `lavendersim._lavender_c` (metadata lives in pyproject.toml).

The extension is the generated C kernels (generated/kernels.c) plus the hand-written stepping loop and
CPython glue (lavendersim/csrc/*.c). The sha256 of the generated C sources (HASHED) is embedded as
`_lavender_c.GENERATED_HASH`, so importing lavendersim.backends.c_backend can tell a stale build.

    pip install -e .                  # editable install; builds the extension in place
    LAVENDERSIM_BUILD_C=0 pip install -e .   # explicit opt-out: NumPy backend only, no compiler needed
    LAVENDERSIM_NATIVE=1 pip install -e .    # add -march=native (not portable; see the measurements)
    LAVENDERSIM_SANITIZE=1 pip install --target DIR .  # AddressSanitizer + UBSan build, for testing only
        (-O1 -g; run Python with LD_PRELOAD=$(gcc -print-file-name=libasan.so); .ci/sanitize does it all)

A missing or failing C compiler stops the build with an explanation; it is never skipped silently.
"""
from __future__ import annotations

import hashlib
import os
import sys
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
        try:
            super().build_extension(ext)
        except Exception as exc:  # noqa: BLE001 - re-raised with context, never swallowed
            raise SystemExit(_explain(exc)) from exc


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


setup(ext_modules=extensions(), cmdclass={"build_ext": BuildExt})
