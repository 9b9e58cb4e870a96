# GraspGuide: stamps the firmware with the first 8 hex digits of the git commit it was
# built from (GRASPGUIDE_BUILD_ID, reported in HELLO_REPLY and so in every session log).
# Only the board's own sources (projenv) get the define, so a new commit rebuilds the
# entry point, not the libraries. Outside a git checkout the id stays 0.
import subprocess

Import("projenv")  # noqa: F821 (SCons)


def _commit_prefix(project_dir):
    try:
        out = subprocess.run(
            ["git", "-C", project_dir, "rev-parse", "--short=8", "HEAD"],
            check=True,
            capture_output=True,
            text=True,
        ).stdout.strip()
        return int(out, 16)
    except (OSError, subprocess.CalledProcessError, ValueError):
        return 0


projenv.Append(
    CPPDEFINES=[
        (
            "GRASPGUIDE_BUILD_ID",  # noqa: F821
            "0x%08xu" % _commit_prefix(projenv.subst("$PROJECT_DIR")),
        )
    ]
)  # noqa: F821
