"""``import mmrl`` asks OpenMP for sleeping waits unless the user chose a policy (README,
"Sharing the cores")."""
import os
import subprocess
import sys


def _policy_after_import(env_value):
    env = {k: v for k, v in os.environ.items() if k != "OMP_WAIT_POLICY"}
    if env_value is not None:
        env["OMP_WAIT_POLICY"] = env_value
    out = subprocess.run([sys.executable, "-c", "import os, mmrl; print(os.environ['OMP_WAIT_POLICY'])"],
                         env=env, capture_output=True, text=True, check=True)
    return out.stdout.strip()


def test_import_sets_a_passive_wait_policy_unless_the_user_chose_one():
    assert _policy_after_import(None) == "PASSIVE"
    assert _policy_after_import("ACTIVE") == "ACTIVE"
