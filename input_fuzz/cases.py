"""Hypothesis strategies of whole ``mjx-arm`` command lines: every subcommand, its flags with
valid, out-of-range and malformed values, its files good, mutated, hostile, missing, of another
kind or special (a FIFO, a device, a socket, a folder, a link), and its output paths beside the
inputs, of 250-byte names, under an absent folder of ``/`` or a user's folder.

A :class:`Case` is an argv whose file arguments are slots (:class:`In`, :class:`Out`); the
harness (:mod:`input_fuzz.harness`) makes the files and puts their paths in. The numbers lean
to small valid values, so that many cases get past the checks and reach the work (which the
harness stops where it would be long).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

from hypothesis import strategies as st

from mjx_arm.names import EVAL_ENGINES, IMPLS, PARITY_ENGINES, PRESET_NAMES, TASKS

# How an input slot is filled: the good file, a generic mutation of it, a structure-aware
# hostile one (:mod:`input_fuzz.hostile`), no file, another kind's file, a special file (a FIFO,
# a device, a socket, a folder, a link; or one of its parts so: :mod:`input_fuzz.special`).
MODES = ("good", "mutated", "hostile", "hostile", "missing", "other", "special")
FILE_KINDS = ("urdf", "arm_file", "arm_json", "config", "policy", "onnx", "trajectory", "run_dir")
FILE_KINDS += ("mesh",)  # a URDF with a mesh and its side files (:mod:`input_fuzz.hostile_mesh`)
# How an output path is named: beside the inputs; a 250-byte file name; deep under a folder
# of / that does not exist; a folder of the user's holding their own files (folders only).
OUT_NAMES = ("", "", "", "", "", "long", "deep")
DIR_NAMES = ("", "", "", "user", "user", "long", "deep")


@dataclass(frozen=True)
class In:
    """An input file of ``kind`` (:data:`FILE_KINDS`), filled by ``mode`` (:data:`MODES`)."""

    kind: str
    mode: str
    seed: int


@dataclass(frozen=True)
class Out:
    """An output path ending in ``suffix``; ``seeded``: a good file is there before the case;
    ``name``: how it is named (:data:`OUT_NAMES`, :data:`DIR_NAMES`)."""

    suffix: str
    seeded: bool
    name: str = ""


@dataclass
class Case:
    """One command line: ``argv`` of texts and slots; ``lock``: another process holds the run
    directories of the case; ``real``: its work runs (not stopped by the harness)."""

    command: str
    argv: list[str | In | Out] = field(default_factory=list)
    lock: bool = False
    real: bool = False


# --------------------------------------------------------------------------- values

GARBAGE = ("", "x", "1.5", "nan", "inf", "-inf", "1e3", "0x10", " 3", "--", "1,2", "é")
BIG = (2**31, 2**32, 2**32 - 1, 2**63, -(2**63), 10**30)


def integer_text(low: int = 0, high: int = 3) -> st.SearchStrategy[str]:
    """An integer as text, mostly in ``[low, high]``, else negative, huge or not a number."""
    return st.one_of(
        st.integers(low, high).map(str),
        st.integers(low, high).map(str),
        st.integers(-5, 5).map(str),
        st.sampled_from(BIG).map(str),
        st.sampled_from(GARBAGE),
    )


def number_text() -> st.SearchStrategy[str]:
    """A number as text: small, negative, huge, non-finite or not a number."""
    return st.one_of(
        st.floats(0.0, 1.0).map(lambda x: f"{x:.3g}"),
        st.floats(allow_nan=True, allow_infinity=True).map(repr),
        st.sampled_from(GARBAGE),
    )


def choice_text(choices) -> st.SearchStrategy[str]:
    """One of ``choices``, or sometimes a wrong name."""
    return st.one_of(st.sampled_from(list(choices)), st.sampled_from(list(choices)), GARBAGE_TEXT)


GARBAGE_TEXT = st.sampled_from(GARBAGE)


def infile(*kinds: str) -> st.SearchStrategy[In]:
    """An input slot of one of ``kinds``; ``other`` mode takes another kind's good file."""
    return st.builds(In, st.sampled_from(kinds), st.sampled_from(MODES), st.integers(0, 2**32 - 1))


def outfile(*suffixes: str) -> st.SearchStrategy[Out]:
    """An output slot, mostly with one of ``suffixes``, else a wrong one; named as
    :data:`OUT_NAMES`."""
    good = st.sampled_from(suffixes) if suffixes else st.just(".out")
    suffix = st.one_of(good, good, good, st.just(".txt"))
    return st.builds(Out, suffix, st.booleans(), st.sampled_from(OUT_NAMES))


def outdir() -> st.SearchStrategy[Out]:
    """An output folder slot, named as :data:`DIR_NAMES` (a user's folder among them)."""
    return st.builds(Out, st.just(""), st.booleans(), st.sampled_from(DIR_NAMES))


def flags(options: dict[str, st.SearchStrategy], most: int = 4) -> st.SearchStrategy[list]:
    """Up to ``most`` of ``options`` (flag -> value strategy; a None value: a switch)."""

    @st.composite
    def build(draw) -> list:
        names = draw(st.lists(st.sampled_from(sorted(options)), max_size=most, unique=True))
        argv: list = []
        for name in names:
            value = options[name]
            argv += [name] if value is None else [name, draw(value)]
        return argv

    return build()


def settings_items(keys: tuple[str, ...]) -> st.SearchStrategy[list[str]]:
    """``--set KEY=VALUE ...`` items: known keys (and a few unknown) with any values."""
    key = st.one_of(st.sampled_from(keys), st.sampled_from(keys), st.just("no_such_key"))
    value = st.one_of(integer_text(1, 64), number_text(), GARBAGE_TEXT)
    item = st.one_of(st.tuples(key, value).map("=".join), GARBAGE_TEXT)
    return st.lists(item, min_size=1, max_size=3).map(lambda items: ["--set", *items])


# --------------------------------------------------------------------------- commands

ARMS = infile("urdf", "arm_file", "arm_json", "mesh")
URDFS = infile("urdf", "mesh")
POLICIES = infile("policy", "policy", "onnx", "run_dir")
LINKS = st.sampled_from(["wrist_3_link", "tool0", "base_link", "no_link", ""])
TRAIN_KEYS = (
    "num_envs",
    "batch_size",
    "num_minibatches",
    "num_timesteps",
    "num_evals",
    "unroll_length",
    "learning_rate",
    "discounting",
    "seed",
    "policy_hidden",
    "physics.njmax",
    "randomization.latency_prob",
    "task.episode_steps",
    "task.action_scale",
    "task.reward.distance",
    "arm.urdf",
)
DEPLOY_KEYS = ("tau", "gain", "lookahead_time", "limiter.acceleration", "servo.position_gain")


def _validate() -> dict:
    return {"--engine": choice_text(("mujoco", "pybullet", "all"))}


def _convert() -> dict:
    return {
        "--scene": choice_text(("none", "reach", "touch", "lift")),
        "--repair-inertia": None,
        "--default-effort": number_text(),
        "--package": st.sampled_from(["ur=.", "x", "=", "p=/no/such"]),
    }


def _train() -> dict:
    return {
        "--task": choice_text(TASKS),
        "--preset": choice_text(PRESET_NAMES),
        "--backend": choice_text(("mujoco", "auto", "mjx")),
        "--devices": integer_text(0, 1),
        "--arm": ARMS,
        "--ee-link": LINKS,
        "--config": infile("config"),
        "--quiet": None,
    }


def _eval() -> dict:
    return {
        "--engine": choice_text(EVAL_ENGINES),
        "--impl": choice_text(IMPLS),
        "--episodes": integer_text(1, 2),
        "--seed": integer_text(0, 5),
        "--task": choice_text(TASKS),
        "--arm": ARMS,
        "--pybullet-contact": st.sampled_from(["soft", "rigid", "4e4:200", "nan:1", "x", "1:2/3"]),
        "--video": outfile(".mp4", ".gif"),
        "--width": integer_text(16, 64),
        "--trajectory": outfile(".npz"),
        "-o": outfile(".json"),
        "--step": integer_text(0, 10_240),
    }


def _case(command: str, head: list, positional: list, options: dict, most: int = 4):
    """A strategy of :class:`Case` for ``command``: ``head`` words, then ``positional`` slot
    strategies, then some of ``options``."""

    @st.composite
    def build(draw) -> Case:
        argv = list(head) + [draw(p) for p in positional] + draw(flags(options, most))
        return Case(command, argv)

    return build()


def _train_case():
    @st.composite
    def build(draw) -> Case:
        argv = ["train", "--quiet"]
        if draw(st.booleans()):  # a resumed run takes its config from the run directory
            argv += ["--resume", draw(infile("run_dir"))]
        else:
            argv += ["--preset", "cpu", "--backend", "mujoco"]
            argv += ["--run-dir", draw(st.one_of(outdir(), infile("run_dir")))]
            argv += draw(flags(_train(), 3))
            if draw(st.booleans()):
                argv += draw(settings_items(TRAIN_KEYS))
        return Case("train", argv, lock=draw(st.integers(0, 9)) == 0)

    return build()


def _bench(name: str, options: dict, positional: tuple = ()) -> st.SearchStrategy[Case]:
    out = {"--out": st.one_of(outdir(), infile("config"))}
    return _case(f"bench {name}", ["bench", name], list(positional), {**options, **out})


# A quick parity run of the CPU engines, run whole, where --out is not given: it writes into
# runs/ of the working folder, never into benchmarks/results (about 8 s).
QUICK_PARITY = ["bench", "parity", "--quick", "--engines", "mujoco", "pybullet"]
REAL_PARITY_EVERY = 12  # about one bench parity case in this many


def _parity() -> st.SearchStrategy[Case]:
    fuzzed = _bench(
        "parity",
        {
            "--quick": None,
            "--engines": choice_text(PARITY_ENGINES),
            "--fk-poses": integer_text(1, 8),
            "--seconds": number_text(),
            "--amplitude": number_text(),
            "--press-boxes": integer_text(1, 8),
            "--seed": integer_text(0, 5),
            "--arm": ARMS,
        },
    )
    seeds = st.integers(0, 999).map(str)  # each a new run (Hypothesis draws no example twice)
    real = seeds.map(lambda seed: Case("bench parity", [*QUICK_PARITY, "--seed", seed], real=True))
    pick = st.integers(0, REAL_PARITY_EVERY - 1)
    return pick.flatmap(lambda n: real if n == 0 else fuzzed)


CASES: dict[str, Callable[[], st.SearchStrategy[Case]]] = {
    "validate": lambda: _case("validate", ["validate"], [URDFS], _validate()),
    "convert": lambda: _case(
        "convert", ["convert"], [URDFS, st.just("-o"), outfile(".xml")], _convert()
    ),
    "arm": lambda: _case(
        "arm",
        ["arm"],
        [ARMS],
        {
            "--ee-link": LINKS,
            "-o": outfile(".toml"),
            "--check": None,
            "--picture": outfile(".png", ".jpg"),
        },
        2,
    ),
    "train": _train_case,
    "export": lambda: _case(
        "export",
        ["export"],
        [infile("run_dir"), st.just("-o"), outfile(".npz", ".onnx")],
        {"--step": integer_text(0, 10_240), "-o": outfile(".npz", ".onnx")},
        2,
    ),
    "eval": lambda: _case("eval", ["eval", "--episodes", "1"], [POLICIES], _eval(), 5),
    "replay": lambda: _case(
        "replay",
        ["replay"],
        [infile("trajectory", "trajectory", "policy"), st.just("-o"), outfile(".png")],
        {
            "--video": outfile(".mp4"),
            "--width": integer_text(16, 200),
            "--task": choice_text(TASKS),
        },
        3,
    ),
    "deploy-sim": lambda: st.builds(
        lambda case, items: Case(case.command, case.argv + items),
        _case(
            "deploy-sim",
            ["deploy-sim", "--episodes", "1"],
            [POLICIES],
            {
                "--engine": choice_text(("mujoco", "pybullet")),
                "--episodes": integer_text(1, 2),
                "--seed": integer_text(0, 5),
                "--arm": ARMS,
                "--script": outfile(".script"),
                "--trajectory": outfile(".json"),
                "-o": outfile(".json"),
            },
        ),
        st.one_of(st.just([]), settings_items(DEPLOY_KEYS)),
    ),
    "demo": lambda: _case("demo", ["demo", "--quick"], [], {"--out": outdir(), "--arm": ARMS}, 2),
    "bench parity": _parity,
    "bench grasp": lambda: _bench("grasp", {"--engines": choice_text(PARITY_ENGINES)}),
    "bench transfer": lambda: _bench(
        "transfer",
        {
            "--episodes": integer_text(1, 5),
            "--seed": integer_text(0, 5),
            "--goal-success": number_text(),
            "--pybullet-contact": st.sampled_from(["soft", "rigid", "x", "inf:1"]),
            "--task": choice_text(("", *TASKS)),
        },
        (POLICIES,),
    ),
    "bench seeds": lambda: _bench(
        "seeds",
        {
            "--seeds": st.sampled_from(["0", "0-2", "3,1", "2-1", "a", "", "0,0", "0-5000"]),
            "--threshold": number_text(),
            "--devices": integer_text(0, 1),
            "--preset": choice_text(PRESET_NAMES),
            "--arm": ARMS,
        },
    ),
}


def cases(commands: tuple[str, ...] | None = None) -> st.SearchStrategy[Case]:
    """A command line of one of ``commands`` (default: all of :data:`CASES`)."""
    names = sorted(commands or CASES)
    return st.sampled_from(names).flatmap(lambda name: CASES[name]())
