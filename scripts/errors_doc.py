#!/usr/bin/env python3
"""Regenerates the front-end part of docs/errors.md from tests/golden/errors/ (run from the
crate root after `UPDATE_GOLDEN=1 cargo test --release`). Data and command codes (E02xx,
E03xx, E04xx...) are documented by hand below the generated part."""
import pathlib, re

ROOT = pathlib.Path(__file__).resolve().parent.parent
DESCRIPTIONS = {
    "E0001": ("syntax", "The parser met a token it did not expect. The message says what would have been accepted, in words (a name, a number, a declaration...), and what was found."),
    "E0002": ("syntax", "Brackets nested more than 200 levels deep. Split the expression with `let`s."),
    "E0003": ("syntax", "One declaration holds more than 2000 operators, or a chain of more than 200 operators in a row (e.g. `- - - ... x`)."),
    "E0004": ("syntax", "A number that is not a finite 64-bit float (`1e400`), or a whole number too large for `dim` or a layer width."),
    "E0005": ("syntax", "A declaration in a place it is not allowed: `der X += ...` outside an effect, an effect inside an effect, a `noise` declaration inside an effect."),
    "E0006": ("file", "The model file is not UTF-8 text (binary data). Tested in tests/it/cli.rs."),
    "E0008": ("file", "The model file cannot be read (missing, permissions). Tested in tests/it/cli.rs."),
    "E0101": ("check", "A name that is not declared. The help line suggests the nearest declared name."),
    "E0102": ("check", "A name declared twice (all names of a model share one namespace; effects may not reuse top-level names)."),
    "E0103": ("check", "A state (measured or hidden) without a `der` or `next` equation."),
    "E0104": ("check", "A state with two balance equations."),
    "E0105": ("check", "`der`/`next` of something that is not a state (an input, const, param, let...)."),
    "E0106": ("check", "A closure output that no balance, `let` or `output` uses."),
    "E0107": ("check", "A cycle among `let`s, `output`s or `const`s."),
    "E0108": ("check", "A model with both `der` and `next` equations."),
    "E0109": ("check", "A bad embedding: `dim` below 1, a `delay` that is not positive, or `dim` above 1 without a delay."),
    "E0110": ("check", "A `prior` for a name that is not an output of that closure."),
    "E0111": ("check", "A `positive` param whose initial value is zero or negative."),
    "E0112": ("check", "An unknown activation in `network` (softplus, tanh, relu, sigmoid, gelu, linear)."),
    "E0113": ("check", "An unknown function (exp, log, sqrt, abs, tanh, sigmoid, softplus, min, max, pow)."),
    "E0114": ("check", "A function called with the wrong number of arguments."),
    "E0115": ("check", "An effect patches a name that does not exist."),
    "E0116": ("check", "An effect patches something that cannot be patched (a state, input or param)."),
    "E0117": ("check", "A value that must be constant (const value, bound, magnitude, delay, initial value) uses a name that is not constant."),
    "E0118": ("check", "Bounds with lo >= hi, a param starting outside its bounds, or a constant that evaluates to infinity or NaN."),
    "E0119": ("check", "A malformed closure block: no outputs, a repeated line, two priors for one output, a layer width of 0."),
    "E0120": ("check", "A closure observes something that is not measured (a hidden state, a let...)."),
    "E0121": ("check", "A prior uses a closure output directly."),
    "E0122": ("check", "A hidden state of a trainable model (one with closures or params) has no initial value."),
    "E0124": ("check", "A model that declares no measured state."),
    "E0140": ("noise", "A `noise` declaration for something that is not measured: a hidden state, an input, a const, a param or a `let` (only measured `state`s and `output`s have measurement noise). The help says why and what to do (make a `let` an `output` if a sensor reads it)."),
    "E0141": ("noise", "Two `noise` declarations for one quantity (`noise X` twice, or `X` in two lists); both are labelled."),
    "E0142": ("noise", "A negative noise term (`-4 %`, `-0.01`), or an absolute term that is no longer a finite number once converted to the quantity's unit."),
    "E0143": ("noise", "Two relative (`%`) or two absolute terms in one `noise` declaration; a declaration has at most one of each. `noise X = 0.04 + 0.01` is two absolute terms: a relative term is written `4 %`."),
    "E0144": ("noise", "A `noise` declaration whose terms are all zero: give the assay's precision, or leave the declaration out."),
    "E0150": ("units", "A unit symbol gbc does not know, in a `[...]` annotation or after `time` (in a model that declares units). Units are products of powers of `g mol L m K s min h d % ppm` with the SI prefixes `p n u µ m c d k M` (not on `min h d % ppm`), and `-` for dimensionless; the help suggests the symbol meant (`hr` is `h`, `percent` is `%`) or says that a symbol takes no prefix (`m%`)."),
    "E0151": ("units", "Two units of different dimensions where one unit is needed: the operands of `+ - min max`, a balance `der X` (the unit of `X` per time unit) or `next X`, a prior or `~` magnitude and its output, a definition and its declared unit, an initial value, a bound, a patch, an embedding delay (the time unit). Both units are labelled and named with their dimensions."),
    "E0152": ("units", "Two units of one dimension but different scales (`g/L` and `mg/L`, `1/h` and `1/min`, `h` and `min`, `%` and `-`) where one unit is needed; the message and the help name the factor between them (`1 g/L = 1000 mg/L`)."),
    "E0153": ("units", "Something that must be a pure number has a unit: the argument of `exp`, `log`, `tanh`, `sigmoid` or `softplus`, an exponent, or the factor of a `NAME *= ...` patch."),
    "E0130": ("lowering", "`--effect NAME` names an effect the model does not declare. Tested in tests/it/cli.rs."),
    "E0131": ("lowering", "`let`s nested more than 256 levels deep."),
    "E0132": ("lowering", "Inlining `let`s produced an expression of more than two million nodes."),
    "E0133": ("lowering", "A prior depends on a closure output through `let`s."),
    "E0136": ("lowering", "A term of the balance of a `nonnegative` state uses a closure output and is not provably `>= 0` where the state is zero, for any value of the network's raw outputs (docs/language.md, \"Non-negative states\"): a learned consumption that does not vanish with its substrate. The label is on the term as written (in the balance, a `let` it names, or an effect's patch); the help shows the rewrite that passes: a rate times its substrate (`- k * S * X` with `outputs k ... positive`), or a `*=` prior that vanishes at zero. Terms without a closure output are not judged. With effects applied the message names them; `gbc check` tries each effect alone."),
    "E0134": ("command line", "A `--noise NAME=LEVEL` spec (`gbc simulate`, `gbc diagnose`) names something that is not a measured state or an output of the model; the message says what the name is, the help lists the measured quantities with a \"did you mean\". Tested in tests/it/noise.rs."),
    "E0135": ("command line", "Two `--noise` specs for one quantity, or two bare levels (`--noise 1% --noise 2%`). Tested in tests/it/noise.rs."),
}

def main():
    cases = sorted((ROOT / "tests/golden/errors").glob("E0*.gbm"))
    by_code = {}
    for case in cases:
        by_code.setdefault(case.name.split("_")[0], []).append(case)
    out = ["# Diagnostic codes", "",
           "Every diagnostic gbc prints has a code `gbm::E0xxx`, a label on the offending span and a",
           "help line. Front-end codes (E00xx syntax, E01xx checks and lowering) each have a golden",
           "case in `tests/golden/errors/` whose `.stderr` file shows exactly what a user sees; a test",
           "fails if a code declared in `src/` is missing here or has no case.", "",
           "Internal errors (a bug in gbc: an invariant broken, never a problem with the input) carry",
           "no `gbm::` code: they are one type, `gbc::error::Bug`, with the code `gbc::internal` and the",
           "help \"this is a bug in gbc: please report it\", and `gbc` exits with code 2 for them (1 for",
           "every coded diagnostic). Former codes of internal errors (E0009 parser, E0253 table writer,",
           "E0316 signal, E0400 trainable network, E0809 diagnosis) are retired.", "",
           "<!-- generated by scripts/errors_doc.py from tests/golden/errors; edit the script -->", ""]
    for code, (stage, text) in DESCRIPTIONS.items():
        out.append(f"## {code} ({stage})")
        out.append("")
        out.append(text)
        out.append("")
        for case in by_code.get(code, [])[:1]:
            stderr = case.with_suffix(".stderr")
            out.append(f"Example (`tests/golden/errors/{case.name}`):")
            out.append("")
            out.append("```text")
            body = stderr.read_text().splitlines()[1:] if stderr.exists() else case.read_text().splitlines()
            body = [l for l in body if len(l) < 200] or ["(long generated input; see the file)"]
            out.extend(body[:40])
            out.append("```")
            out.append("")
    out.append("<!-- end of generated part -->")
    doc = ROOT / "docs/errors.md"
    old = doc.read_text() if doc.exists() else ""
    tail = old.split("<!-- end of generated part -->", 1)[1] if "<!-- end of generated part -->" in old else "\n"
    doc.write_text("\n".join(out) + tail)

main()
