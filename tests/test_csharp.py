"""examples/csharp with Debian's Mono (issue 28): the C# binding (MmrlRuntime.cs, P/Invoke with
SafeHandles) and its console program write the same JSON trace as the C++ example on the same
file and targets; the binding's stick decides as the runtime's; the Unity guide's MonoBehaviour
(examples/csharp/unity) compiles against small stand-ins of the Unity types and drives a
Transform hierarchy with the runtime's pose, mirrored into Unity's left-handed frame, from the
GameObject's position and rotation, through a bone map, by a target or a stick. CI installs
mono-mcs and mono-runtime (.ci/run); elsewhere the tests skip with one line when Mono or the
library is missing."""
import json
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

import mmrl
from mmrl import _core
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


STICK_CHECK = r"""
using System;
using Mmrl;

static class StickCheck
{
    static int Main(string[] args)
    {
        using (var controller = MmrlController.Load(args[0]))
        using (var c = controller.CreateCharacter(1f, 2f, 0.5f))
        {
            var pose = new MmrlPose(controller.NumJoints);
            foreach (var v in new[] { new[] { 0f, 0f, 1f }, new[] { float.NaN, 1f, 1f }, new[] { 1f, 0f, 0f },
                                      new[] { 1f, 0f, -2f }, new[] { 1f, 0f, float.PositiveInfinity } })
            {
                try { c.SetStick(v[0], v[1], v[2]); Console.WriteLine("accepted"); }
                catch (MmrlException e) { Console.WriteLine("refused " + e.Status + " " + e.Message); }
            }
            c.SetStick(-3f, 1f, 2f);
            for (int d = 0; d < 200; d++)
            {
                if (d == 150) c.SetTarget(4f, 4f);
                for (int k = 0; k < 6; k++) c.Update(1f / 30f, pose);
                Console.WriteLine("match " + c.LastDecision.Match);
            }
        }
        return 0;
    }
}
"""


def test_the_csharp_stick_decides_as_the_runtime(built):
    """MmrlCharacter.SetStick: 150 decisions by a stick then 50 by a target, the same matches as the
    runtime's binding (whose stick tests/test_runtime.py holds to the joystick's full path); bad
    values throw MmrlException(InvalidArgument) naming the argument."""
    check = built["dir"] / "StickCheck.cs"
    check.write_text(STICK_CHECK)
    exe = built["dir"] / "stick.exe"
    done = subprocess.run([built["mcs"], "-nologo", "-warnaserror+", f"-out:{exe}", str(CS / "MmrlRuntime.cs"),
                           str(check)], capture_output=True, text=True)
    assert done.returncode == 0, done.stdout + done.stderr
    run = subprocess.run([built["mono"], str(exe), str(built["controller"])], env=built["env"], capture_output=True,
                         text=True, timeout=300)
    assert run.returncode == 0, run.stdout + run.stderr
    lines = run.stdout.splitlines()
    refused = lines[:5]
    assert all(line.startswith("refused InvalidArgument stick: the direction (x, z)") for line in refused[:2]), refused
    assert all(line.startswith("refused InvalidArgument stick: the speed must be finite and > 0") for line in
               refused[2:]), refused
    matches = [int(line.split()[1]) for line in lines[5:]]
    ch = _core.RuntimeCharacter(_core.RuntimeController.load(str(built["controller"])), 1.0, 2.0, 0.5)
    ch.set_stick(-3.0, 1.0, 2.0)
    want = []
    for d in range(200):
        if d == 150:
            ch.set_target(4.0, 4.0)
        for _ in range(6):
            ch.update(1.0 / 30.0)
        want.append(ch.last_decision()["match"])
    assert matches == want
    assert len(set(want[:150])) > 10  # not vacuous: the stick's decisions moved through the database


GUIDE_CHECK = r"""
using System;
using System.Collections.Generic;
using System.Globalization;
using System.Reflection;
using Mmrl;
using UnityEngine;

static class GuideCheck
{
    static void Set(object o, string field, object value) =>
        o.GetType().GetField(field, BindingFlags.NonPublic | BindingFlags.Instance).SetValue(o, value);
    static object Get(object o, string field) =>
        o.GetType().GetField(field, BindingFlags.NonPublic | BindingFlags.Instance).GetValue(o);
    static void Call(object o, string method) =>
        o.GetType().GetMethod(method, BindingFlags.NonPublic | BindingFlags.Instance).Invoke(o, null);
    static string F(double v) => v.ToString("R", CultureInfo.InvariantCulture);
    static Quaternion UnityYaw(float degrees)
    {
        double h = 0.5 * degrees * Math.PI / 180.0;
        return new Quaternion(0f, (float)Math.Sin(h), 0f, (float)Math.Cos(h));
    }

    static int Main(string[] args)
    {
        Application.streamingAssetsPath = args[0];
        using (var controller = MmrlController.Load(System.IO.Path.Combine(args[0], args[1])))
        {
            int J = controller.NumJoints;
            // The GameObject away from the origin, turned 40 degrees, with an armature object between it
            // and the rig (moved and turned too): neither may offset the character a second time.
            var hero = new UnityEngine.Transform("hero");
            hero.position = new Vector3(5f, 0.25f, -3f);
            hero.rotation = UnityYaw(40f);
            var armature = new UnityEngine.Transform("Armature", hero);
            armature.localPosition = new Vector3(0.1f, 0f, 0.2f);
            armature.localRotation = UnityYaw(30f);
            // Odd joints renamed ("rig:" + name) through the bone map, beside decoys of the BVH names.
            var map = new List<MmrlCharacterBehaviour.BoneName>();
            var nodes = new UnityEngine.Transform[J];
            var decoys = new List<UnityEngine.Transform>();
            for (int j = 0; j < J; j++)
            {
                int p = controller.JointParent(j);
                string name = controller.JointName(j);
                var parent = p < 0 ? armature : nodes[p];
                if (j % 2 == 1)
                {
                    map.Add(new MmrlCharacterBehaviour.BoneName { joint = name, bone = "rig:" + name });
                    nodes[j] = new UnityEngine.Transform("rig:" + name, parent);
                    decoys.Add(new UnityEngine.Transform(name, armature));
                }
                else
                {
                    nodes[j] = new UnityEngine.Transform(name, parent);
                }
            }
            map.Add(new MmrlCharacterBehaviour.BoneName { joint = "NoSuchJoint", bone = "x" });  // one warning
            var target = new UnityEngine.Transform("target");
            target.position = new Vector3(-3f, 0f, 4f);   // Unity's x is mmrl's -x
            var behaviour = new MmrlCharacterBehaviour();
            behaviour.transform = hero;
            Set(behaviour, "controllerFile", args[1]);
            Set(behaviour, "target", target);
            Set(behaviour, "boneMap", map);
            Call(behaviour, "Start");
            var ours = (MmrlCharacter)Get(behaviour, "character");
            // The twin, through the binding: where the GameObject stands, Unity (5, -3) being mmrl (-5, -3)
            // and Unity's yaw of 40 degrees mmrl's -40.
            using (var twin = controller.CreateCharacter(-5f, -3f, (float)(-40.0 * Math.PI / 180.0)))
            {
                twin.SetTarget(3f, 4f);
                var pose = new MmrlPose(J);
                double rot = 0, pos = 0, follow = 0;
                int mismatches = 0, badStatus = -1;
                Vector3 first = default(Vector3), firstForward = default(Vector3), firstHip = default(Vector3);
                Vector3 stickStart = default(Vector3), stickEnd = default(Vector3);
                for (int f = 0; f < 420; f++)
                {
                    if (f == 120)
                    {
                        stickStart = hero.position;
                        behaviour.SetStick(new Vector2(2f, 0f), 1.5f);   // Unity +x: mmrl -x
                        twin.SetStick(-1f, 0f, 1.5f);
                    }
                    if (f == 300)
                    {
                        stickEnd = hero.position;
                        behaviour.SetTarget(target);
                        twin.SetTarget(3f, 4f);
                    }
                    Call(behaviour, "Update");
                    twin.Update(Time.deltaTime, pose);
                    if (f == 0)
                    {
                        first = hero.position;
                        firstForward = hero.forward;
                        firstHip = nodes[0].position;
                    }
                    float[] q = pose.LocalRotations, x = pose.LocalTranslations, r = pose.Root;
                    for (int j = 0; j < J; j++)
                    {
                        // The twin's pose mirrored: root bones in the world, through the hierarchy; the others local.
                        bool root = controller.JointParent(j) < 0;
                        Quaternion b = root ? nodes[j].rotation : nodes[j].localRotation;
                        rot = Math.Max(rot, Math.Max(Math.Max(Math.Abs(b.w - q[4 * j]), Math.Abs(b.x - q[4 * j + 1])),
                                                     Math.Max(Math.Abs(b.y + q[4 * j + 2]), Math.Abs(b.z + q[4 * j + 3]))));
                        if (!root) continue;
                        Vector3 w = nodes[j].position;
                        pos = Math.Max(pos, Math.Max(Math.Abs(w.x + x[3 * j]),
                                                     Math.Max(Math.Abs(w.y - 0.25f - x[3 * j + 1]), Math.Abs(w.z - x[3 * j + 2]))));
                    }
                    // The GameObject follows the character frame.
                    Vector3 h = hero.position, fw = hero.forward;
                    follow = Math.Max(follow, Math.Max(Math.Abs(h.x + r[0]), Math.Max(Math.Abs(h.y - 0.25f), Math.Abs(h.z - r[1]))));
                    follow = Math.Max(follow, Math.Max(Math.Abs(fw.x + Math.Sin(r[2])), Math.Abs(fw.z - Math.Cos(r[2]))));
                    if (ours.LastDecision.Match != twin.LastDecision.Match) mismatches++;
                }
                try { behaviour.SetStick(Vector2.zero, 1f); }
                catch (MmrlException e) { badStatus = (int)e.Status; }
                bool decoysStill = true;
                foreach (var d in decoys)
                    decoysStill &= d.localRotation.w == 1f && d.localRotation.x == 0f && d.localPosition.x == 0f;
                Console.WriteLine("rot " + F(rot) + " pos " + F(pos) + " follow " + F(follow) + " mismatches " + mismatches +
                                  " warnings " + UnityEngine.Debug.Warnings.Count + " first " + F(first.x) + " " + F(first.y) + " " +
                                  F(first.z) + " forward " + F(firstForward.x) + " " + F(firstForward.z) + " hip " + F(firstHip.x) +
                                  " " + F(firstHip.z) + " stick " + F(stickEnd.x - stickStart.x) + " " + F(stickEnd.z - stickStart.z) +
                                  " end " + F(twin.Root[0]) + " " + F(twin.Root[1]) + " bad " + badStatus + " decoys " + decoysStill);
                foreach (var w in UnityEngine.Debug.Warnings) Console.WriteLine("warning " + w);
            }
            Call(behaviour, "OnDestroy");
        }
        return 0;
    }
}
"""


def test_the_unity_guide_compiles_and_drives_a_transform_hierarchy(built):
    """The guide's script on a stand-in rig under a GameObject at (5, 0.25, -3) turned 40 degrees,
    with a moved and turned armature object between them, odd bones renamed through the bone map
    (beside decoys carrying the BVH names), driven by a target, then a stick, then the target again:
    every bone equals a twin character created through the binding at the mirrored start, mirrored
    (root bones in the world, through the hierarchy: no offset counted twice), the GameObject
    follows the character frame, and the stick moves it along Unity's +x."""
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
    lines = run.stdout.splitlines()
    w = lines[0].split()
    out = {}  # "name value value ..." pairs
    for token in w:
        if token.isalpha() and token not in ("True", "False"):
            key = out.setdefault(token, [])
        else:
            key.append(token)

    def num(name, k=0):
        return float(out[name][k])

    # The twin is the behaviour's character: the same decisions, poses within float rounding (its
    # yaw comes from the GameObject's rotation), root bones placed in the world once.
    assert int(out["mismatches"][0]) == 0 and num("rot") <= 1e-5 and num("pos") <= 1e-4 and num("follow") <= 1e-4, w
    # It started where the GameObject stood, facing its forward (one frame later).
    assert np.hypot(num("first") - 5.0, num("first", 2) - (-3.0)) < 0.1 and num("first", 1) == 0.25, w
    assert num("forward") * np.sin(np.radians(40)) + num("forward", 1) * np.cos(np.radians(40)) > 0.99, w
    assert np.hypot(num("hip") - 5.0, num("hip", 1) - (-3.0)) < 0.5, w
    # The stick (Unity +x at 1.5 m/s for 6 s) took it along +x; the target (mmrl (3, 4)) after it.
    assert num("stick") > 4.0 and abs(num("stick", 1)) < 0.5 * num("stick"), w
    # The bone map: the renamed bones were driven (rot above), the decoys left alone, one warning for
    # the map's unknown joint.
    assert out["decoys"][0] == "True" and int(out["warnings"][0]) == 1 and "NoSuchJoint" in lines[1], lines
    assert int(out["bad"][0]) == 1  # SetStick(Vector2.zero): MmrlException(InvalidArgument)
