"""examples/csharp with Debian's Mono (issue 28): the C# binding (MmrlRuntime.cs, P/Invoke with
SafeHandles) and its console program write the same JSON trace as the C++ example on the same
file and targets; the Unity guide's MonoBehaviour (examples/csharp/unity) compiles against small
stand-ins of the Unity types and drives a Transform hierarchy with the runtime's pose, mirrored
into Unity's left-handed frame. CI installs mono-mcs and mono-runtime (.ci/run); elsewhere the
tests skip with one line when Mono or the library is missing."""
import json
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

import mmrl
from mmrl.export.runtime_export import write_controller
from mmrl.tasks.plane import PlaneConfig
from test_capi import library_path
from test_runtime import random_plane_policy
from test_runtime_example import TARGETS, example_binary

ROOT = Path(__file__).resolve().parents[1]
CS = ROOT / "examples" / "csharp"


def mono_tools():
    mcs, mono = shutil.which("mcs"), shutil.which("mono")
    if mcs and mono:
        return mcs, mono
    if os.environ.get("CI"):
        pytest.fail("Mono is not installed (apt-get install mono-mcs mono-runtime)")
    pytest.skip("the C# tests need Mono: apt-get install mono-mcs mono-runtime")


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    mcs, mono = mono_tools()
    lib = library_path()
    out = tmp_path_factory.mktemp("csharp")
    exe = out / "mmrl_trace.exe"
    subprocess.run([mcs, "-nologo", "-warnaserror+", f"-out:{exe}", str(CS / "MmrlRuntime.cs"), str(CS / "Program.cs")],
                   check=True, capture_output=True, text=True)
    env = dict(os.environ, LD_LIBRARY_PATH=f"{lib.parent}:{os.environ.get('LD_LIBRARY_PATH', '')}")
    controller = out / "plane.mmrl"
    write_controller(controller, mmrl.default_database(), random_plane_policy(2), "plane",
                     PlaneConfig(transition_cost=5.0))
    return {"mcs": mcs, "mono": mono, "exe": exe, "env": env, "controller": controller, "dir": out}


def test_the_csharp_trace_equals_the_cpp_example(built, tmp_path):
    targets = ";".join(f"{x},{z}" for x, z in TARGETS)
    args = [str(built["controller"]), "--characters", "3", "--decisions", "200", "--targets", targets]
    cs, cpp = tmp_path / "cs.jsonl", tmp_path / "cpp.jsonl"
    done = subprocess.run([built["mono"], str(built["exe"]), *args, "--trace", str(cs)], env=built["env"],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    ex = subprocess.run([str(example_binary()), *args, "--trace", str(cpp)], capture_output=True, text=True,
                        timeout=300)
    assert ex.returncode == 0, ex.stderr
    a, b = cs.read_text().splitlines(), cpp.read_text().splitlines()
    assert len(a) == len(b) == 600
    assert a == b  # the same numbers, printed the same way
    assert sum(json.loads(line)["transition"] for line in a) >= 10
    # Under a request too; and a bad request is one line naming the tags.
    for prog in ([built["mono"], str(built["exe"])], [str(example_binary())]):
        out = tmp_path / "req.jsonl"
        r = subprocess.run([*prog, *args[:3], "--decisions", "50", "--request", "gait=walk", "--trace", str(out)],
                           env=built["env"], capture_output=True, text=True, timeout=300)
        assert r.returncode == 0, r.stderr
        frames = [json.loads(line)["frame"] for line in out.read_text().splitlines()]
        db = mmrl.default_database()
        assert db.clip_tags[db.frame_clip[frames], db.tag_names.index("gait=walk")].all()
    bad = subprocess.run([built["mono"], str(built["exe"]), str(built["controller"]), "--request", "gait=fly"],
                         env=built["env"], capture_output=True, text=True, timeout=120)
    assert bad.returncode == 2 and "no tag 'gait=fly'" in bad.stderr
    missing = subprocess.run([built["mono"], str(built["exe"]), str(tmp_path / "none.mmrl")], env=built["env"],
                             capture_output=True, text=True, timeout=120)
    assert missing.returncode == 2 and "none.mmrl" in missing.stderr


GUIDE_CHECK = r"""
using System;
using System.Reflection;
using Mmrl;
using UnityEngine;

static class GuideCheck
{
    static void Set(object o, string field, object value) =>
        o.GetType().GetField(field, BindingFlags.NonPublic | BindingFlags.Instance).SetValue(o, value);
    static void Call(object o, string method) =>
        o.GetType().GetMethod(method, BindingFlags.NonPublic | BindingFlags.Instance).Invoke(o, null);

    static int Main(string[] args)
    {
        Application.streamingAssetsPath = args[0];
        using (var controller = MmrlController.Load(System.IO.Path.Combine(args[0], args[1])))
        {
            // A rig with the controller's joints, by name, under one root.
            var rig = new UnityEngine.Transform("rig");
            var nodes = new UnityEngine.Transform[controller.NumJoints];
            for (int j = 0; j < nodes.Length; j++)
            {
                int p = controller.JointParent(j);
                nodes[j] = new UnityEngine.Transform(controller.JointName(j), p < 0 ? rig : nodes[p]);
            }
            var target = new UnityEngine.Transform("target");
            target.position = new Vector3(-3f, 0f, 4f);   // Unity's x is mmrl's -x
            var behaviour = new MmrlCharacterBehaviour();
            behaviour.transform = rig;
            Set(behaviour, "controllerFile", args[1]);
            Set(behaviour, "target", target);
            Call(behaviour, "Start");
            // The same character through the binding: its pose, mirrored, must be what the rig shows.
            using (var twin = controller.CreateCharacter(0f, 0f, 0f))
            {
                twin.SetTarget(3f, 4f);
                var pose = new MmrlPose(controller.NumJoints);
                double worst = 0;
                for (int f = 0; f < 90; f++)
                {
                    Call(behaviour, "Update");
                    twin.Update(Time.deltaTime, pose);
                    for (int j = 0; j < nodes.Length; j++)
                    {
                        var q = nodes[j].localRotation;
                        worst = Math.Max(worst, Math.Abs(q.w - pose.LocalRotations[4 * j]));
                        worst = Math.Max(worst, Math.Abs(q.x - pose.LocalRotations[4 * j + 1]));
                        worst = Math.Max(worst, Math.Abs(q.y + pose.LocalRotations[4 * j + 2]));
                        worst = Math.Max(worst, Math.Abs(q.z + pose.LocalRotations[4 * j + 3]));
                    }
                    var r = nodes[0].localPosition;
                    worst = Math.Max(worst, Math.Abs(r.x + pose.LocalTranslations[0]));
                    worst = Math.Max(worst, Math.Abs(r.z - pose.LocalTranslations[2]));
                }
                Console.WriteLine("worst " + worst.ToString(System.Globalization.CultureInfo.InvariantCulture) +
                                  " root " + twin.Root[0].ToString(System.Globalization.CultureInfo.InvariantCulture) +
                                  " " + twin.Root[1].ToString(System.Globalization.CultureInfo.InvariantCulture) +
                                  " warnings " + UnityEngine.Debug.Warnings.Count);
            }
            Call(behaviour, "OnDestroy");
        }
        return 0;
    }
}
"""


def test_the_unity_guide_compiles_and_drives_a_transform_hierarchy(built):
    check = built["dir"] / "GuideCheck.cs"
    check.write_text(GUIDE_CHECK)
    exe = built["dir"] / "guide.exe"
    unity = CS / "unity"
    done = subprocess.run([built["mcs"], "-nologo", f"-out:{exe}", str(CS / "MmrlRuntime.cs"),
                           str(unity / "UnityEngineStubs.cs"), str(unity / "MmrlCharacterBehaviour.cs"), str(check)],
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stdout + done.stderr
    run = subprocess.run([built["mono"], str(exe), str(built["dir"]), built["controller"].name], env=built["env"],
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stdout + run.stderr
    words = run.stdout.split()
    worst, x, z, warnings = float(words[1]), float(words[3]), float(words[4]), int(words[6])
    assert worst == 0.0 and warnings == 0
    assert np.hypot(x - 3.0, z - 4.0) < np.hypot(3.0, 4.0) - 1.0  # it walked towards the target
