"""The C++ text of src/harness/stage_counts/stage_scenes.h: one StageScene initialiser per
scene and the header around them. tools/scripts/gen_stage_scenes.py writes the checked-in
scene set with it; `graspguide bench agreement m4f` writes other scene sets into
worktrees with it, so both read the same layout."""

from __future__ import annotations

import math

POLICY = {"F": "graspguide::Policy::kF", "Fperp": "graspguide::Policy::kFperp"}
MODE = {"C": "graspguide::Mode::kC", "V": "graspguide::Mode::kV"}
MODEL = {
    "paper": "graspguide::ConstraintModel::kPaper",
    "normal": "graspguide::ConstraintModel::kNormal",
    "none": "graspguide::ConstraintModel::kNone",
}


def f32(x: float) -> str:
    if math.isnan(x):
        return "NAN"
    if math.isinf(x):
        return "INFINITY" if x > 0 else "-INFINITY"
    return f"{x!r}f" if "e" in repr(x) or "." in repr(x) else f"{x!r}.0f"


def arr(xs) -> str:
    return "{" + ", ".join(f32(float(x)) for x in xs) + "}"


def scene_line(
    name: str,
    k: int,
    contacts: list,
    wrench: list,
    y_axis: list,
    orientation: list,
    policy: str,
    mode: str,
    constraints: str,
    status: str,
    pwm: list,
) -> str:
    """One StageScene initialiser; contacts and PWM are padded to 4."""
    contacts = [list(p) for p in contacts] + [[0.0, 0.0, 0.0]] * (4 - len(contacts))
    pwm = list(pwm) + [0] * (4 - len(pwm))
    return (
        f'  {{"{name}", {k}, {{{", ".join(arr(p) for p in contacts)}}}, '
        f"{arr(wrench)}, {arr(y_axis)}, {arr(orientation)}, "
        f"{POLICY[policy]}, {MODE[mode]}, {MODEL[constraints]}, "
        f'"{status}", {{{", ".join(str(int(p)) for p in pwm)}}}}},'
    )


def header(scene_lines: list[str], note: list[str]) -> str:
    """The whole stage_scenes.h around the scene lines; `note` heads it as comments."""
    lines = [f"// {n}" for n in note] + [
        "#pragma once",
        "#include <cmath>",
        "#include <cstdint>",
        "",
        '#include "graspguide/scene.h"',
        "",
        "namespace stages {",
        "struct StageScene {",
        "  const char* name;",
        "  int k;",
        "  float contacts[4][3];",
        "  float wrench[6];",
        "  float y_axis[3];",
        "  float orientation[4];",
        "  graspguide::Policy policy;",
        "  graspguide::Mode mode;",
        "  graspguide::ConstraintModel constraints;",
        "  const char* status;  // the float64 reference's status name",
        "  int16_t pwm[4];      // the reference's PWM (0 when status is not ok)",
        "};",
        "inline const StageScene kStageScenes[] = {",
    ]
    lines += scene_lines
    lines += [
        "};",
        f"inline constexpr int kStageSceneCount = {len(scene_lines)};",
        "}  // namespace stages",
        "",
    ]
    return "\n".join(lines)


__all__ = ["header", "scene_line"]
