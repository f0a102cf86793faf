"""The ``retarget`` command line: retarget feature-point animation onto a mesh from files.

Subcommands (``retarget <command> --help`` for the details):

``transfer``
    Dutreve et al. 2008 §4 end to end: a target mesh and its landmarks T0, a source's
    neutral points S0 and frames S, skin weights computed (or read with ``--rig``), and
    the deformed target written as an (F, V, 3) float32 ``.npy``.
``rig``
    Only the skin weights (Dutreve §3), written as an ``.npz`` that ``transfer --rig``
    reuses, so a slow solve (biharmonic, Laplacian) runs once per mesh.
``demo``
    The built-in example: the sample face driven by another identity's landmarks, with
    the error against the known answer. Needs no files.
``layouts``
    The landmark layouts and the names ``--mask`` accepts.
``track``
    A performance video -> (F, N, 3) source points per frame: ring markers (Dutreve §5,
    one camera, z = 0), a colour-marker stereo pair (Woodward §5) or markerless face-mesh
    tracking (the web app's browser tracker, run in a headless Chromium).
``condition``
    A performance file (landmark table, TRC/C3D motion capture, animated glTF face, OBJ
    sequence, a tracked take) read in a layout's order and conditioned as the app plays a
    take (neutral, head pose, filter, gain) into S0 and S for ``transfer``/``export-gltf``.
``calibrate``
    A stereo camera pair's calibration from checkerboard or circle-grid views, for
    ``track --method stereo``.
``export-gltf``
    The target mesh rigged (feature points as joints of a glTF skin, or morph targets
    for rigs with negative weights) and, given a source, the retargeted take animated,
    as one glTF 2.0 binary (`retarget.gltf`); ``--drive muscles`` the face with its
    muscles, ``--drive arkit`` with ARKit's 52 blendshapes as named morph targets animated
    by the solved weights (``--weights-out``: also as Live Link Face CSV, as ``transfer
    --drive arkit`` writes them).
``arkit``
    ARKit's 52 blendshapes generated on a face from its landmarks (`retarget.arkit`): one
    dense morph target per ARKit name, as an ``.npz``.
``landmarks``
    A face mesh's feature points in a layout found with no clicks (`retarget.facemesh`:
    MediaPipe's face mesh on pictures of the mesh, carried back onto the surface), with a
    confidence per point.
``open-mouth``
    A mesh whose lips are joined (most scans and sculpts) cut open along the lip contact
    line (`retarget.lips`), original vertices first, the cut's duplicates appended.
``muscles``
    Woodward et al.'s 21 virtual muscles and the jaw placed on a face from its landmarks
    (`retarget.muscles`), as JSON for ``transfer --drive muscles``.
``recognise``
    The expression of each frame (neutral or one of six) from muscle contractions, with
    the distances and a confidence, as CSV (Woodward §10).

``batch``
    Every take of a manifest (YAML/JSON) retargeted onto every character, the outputs
    (glTF, ARKit CSV, vertices) in a folder per character and take, on a Dask cluster or
    in this process, resumable (`retarget.batch`).

``serve`` (the web app) is the server's: `server.cli` owns the installed ``retarget``
command and adds it to this parser, so the library never imports the web stack; ``python -m
retarget.cli`` runs the library's commands alone.

One module per command family: `retargeting` (transfer, rig, export-gltf, demo), `sources`
(track, condition, calibrate), `arkit`, `batch`, `mouth` (open-mouth), `landmarks`, `muscles`
(muscles, recognise), `layouts`; `parser` holds what their parsers share. The
work is the library's (`retarget.files` reads, checks and writes the files).

The CLI only parses, calls the library and serialises. Every refusal (a `RetargetError`,
a missing or unreadable file, arrays that do not agree) is one line
``retarget: error: <message>`` on stderr and exit status 2; success is status 0.
Progress bars (tqdm) go to stderr, the results to stdout; ``--quiet`` hides the bars.
"""

from __future__ import annotations

import argparse
import os
import sys

from retarget import __version__
from retarget.cli import arkit, batch, landmarks, layouts, mouth, muscles, retargeting, sources
from retarget.cli.parser import PROG, Parser, UsageError, quiet_option
from retarget.errors import RetargetError

__all__ = ["PROG", "build_parser", "main"]


def build_parser() -> Parser:
    """The ``retarget`` argument parser (refusals raise `UsageError`, see `main`); its
    ``commands`` take more subcommands."""
    quiet = [quiet_option()]
    parser = Parser(
        prog=PROG,
        description="Facial animation retargeting from feature points (Dutreve et al. 2008).",
        epilog=f"'{PROG} demo' runs a complete example that needs no files.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    commands = parser.add_subparsers(dest="command", metavar="COMMAND", required=True,
                                     parser_class=Parser)
    parser.commands = commands
    retargeting.add_transfer(commands, quiet)
    retargeting.add_rig(commands, quiet)
    retargeting.add_demo(commands, quiet)
    sources.add_track(commands, quiet)
    sources.add_condition(commands, quiet)
    sources.add_calibrate(commands, quiet)
    retargeting.add_export_gltf(commands, quiet)
    arkit.add_arkit(commands)
    mouth.add_open_mouth(commands)
    landmarks.add_landmarks(commands)
    muscles.add_muscles(commands)
    muscles.add_recognise(commands, quiet)
    layouts.add_layouts(commands)
    batch.add_batch(commands, quiet)
    return parser


def main(argv: list[str] | None = None, *, parser: argparse.ArgumentParser | None = None) -> int:
    """Run the ``retarget`` command line; returns the exit status (0, or 2 on error).

    parser : the parser to run (default `build_parser()`); `server.cli` passes its own.
    """
    parser = build_parser() if parser is None else parser
    try:
        args = parser.parse_args(argv)
        return args.run(args)
    except UsageError as exc:
        sys.stderr.write(exc.usage)
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return 2
    except SystemExit as exc:  # --help and --version
        return exc.code if isinstance(exc.code, int) else 0
    except BrokenPipeError:  # stdout closed early (`retarget layouts | head -1`)
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 1
    except (RetargetError, OSError) as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return 2
