// MmrlCharacterBehaviour.cs: a Unity MonoBehaviour that drives a character's Transform hierarchy
// with an exported mmrl controller (docs/engines.md). Put MmrlRuntime.cs beside it, the library
// (libmmrl_runtime_c.so / mmrl_runtime_c.dll) in Assets/Plugins, and the controller file in
// Assets/StreamingAssets.
//
// Frames. mmrl's world is right-handed with Y up (BVH): yaw 0 faces +Z and +X is the character's
// left. Unity's is left-handed with Y up. The script mirrors through the YZ plane both ways: a
// position (x, y, z) becomes (-x, y, z), a rotation (w, x, y, z) becomes (w, x, -y, -z), and so
// an mmrl yaw of a radians is a Unity yaw (eulerAngles.y) of -a.
//
// Placement. The runtime's world is Unity's world, mirrored. The character starts where the
// GameObject stands, facing its forward (the yaw of transform.rotation; pitch and roll are
// ignored), on the ground at the GameObject's height. From then on the GameObject follows the
// character frame (position and yaw), the rig's root bones are placed in the world
// (Transform.position and rotation) and the other bones get their local rotations: whatever
// lies between the GameObject and the root bone, nothing offsets the character twice.
//
// Driving. A target Transform (SetTarget), or a stick (SetStick: a direction on the ground and a
// speed, e.g. a gamepad's), whichever was set last.
using System;
using System.Collections.Generic;
using System.IO;
using Mmrl;
using UnityEngine;

public class MmrlCharacterBehaviour : MonoBehaviour
{
    // A rig bone for a BVH joint whose name differs (e.g. "Hips" -> "mixamorig:Hips").
    [Serializable]
    public class BoneName
    {
        public string joint;   // the controller's joint name (MmrlController.JointName)
        public string bone;    // the rig's transform for it
    }

    [SerializeField] string controllerFile = "plane.mmrl";   // in Assets/StreamingAssets
    [SerializeField] Transform target;                        // where the character should go
    [SerializeField] Transform skeletonRoot;                  // the rig's root bone or above (default: this object)
    [SerializeField] List<BoneName> boneMap = new List<BoneName>();  // joints absent from it: same-name bones
    [SerializeField] string request = "";                     // e.g. "style=elderly" (docs/styles.md)

    MmrlController controller;
    MmrlCharacter character;
    MmrlPose pose;
    Transform[] bones;   // per mmrl joint, the rig's transform (null if missing)
    bool[] isRoot;       // per mmrl joint, no parent: placed in the world
    float ground;        // the GameObject's height at Start
    bool stick;          // driven by SetStick, not by the target
    string appliedRequest = "";

    void Start()
    {
        controller = MmrlController.Load(Path.Combine(Application.streamingAssetsPath, controllerFile));
        Vector3 p = transform.position, f = transform.forward;
        ground = p.y;
        character = controller.CreateCharacter(-p.x, p.z, Mathf.Atan2(-f.x, f.z));
        pose = new MmrlPose(controller.NumJoints);
        var byName = new Dictionary<string, Transform>();
        foreach (Transform t in (skeletonRoot != null ? skeletonRoot : transform).GetComponentsInChildren<Transform>())
            byName[t.name] = t;
        var rename = new Dictionary<string, string>();
        foreach (BoneName pair in boneMap) rename[pair.joint] = pair.bone;
        bones = new Transform[controller.NumJoints];
        isRoot = new bool[bones.Length];
        for (int j = 0; j < bones.Length; j++)
        {
            string joint = controller.JointName(j), bone;
            if (rename.TryGetValue(joint, out bone)) rename.Remove(joint);
            else bone = joint;
            Transform t;
            if (!byName.TryGetValue(bone, out t)) Debug.LogWarning("mmrl: no transform named " + bone + " for joint " + joint);
            bones[j] = t;
            isRoot[j] = controller.JointParent(j) < 0;
        }
        foreach (string joint in rename.Keys) Debug.LogWarning("mmrl: the bone map names " + joint + ", which the controller lacks");
    }

    // A stick in place of the target from the next decision on: a direction on Unity's ground
    // plane (direction.x along world x, direction.y along world z; any length > 0) and a speed
    // in m/s (> 0). MmrlException for a zero or non-finite direction or a bad speed.
    public void SetStick(Vector2 direction, float speed)
    {
        if (character == null) throw new InvalidOperationException("SetStick: the character is created in Start");
        character.SetStick(-direction.x, direction.y, speed);
        stick = true;
    }

    // Back to a target Transform (null: stay where the character stands), from the next decision on.
    public void SetTarget(Transform newTarget)
    {
        target = newTarget;
        stick = false;
        if (character == null) return;
        Vector3 t = target != null ? target.position : transform.position;
        character.SetTarget(-t.x, t.z);
    }

    void Update()
    {
        if (character == null) return;
        if (request != appliedRequest)
        {
            character.SetRequest(request);   // MmrlException lists the tags the file has
            appliedRequest = request;
        }
        if (!stick && target != null)
        {
            Vector3 t = target.position;
            character.SetTarget(-t.x, t.z);
        }
        character.Update(Mathf.Min(Time.deltaTime, 1f), pose);
        float[] q = pose.LocalRotations, x = pose.LocalTranslations, r = pose.Root;
        transform.position = new Vector3(-r[0], ground, r[1]);
        transform.rotation = new Quaternion(0f, -Mathf.Sin(0.5f * r[2]), 0f, Mathf.Cos(0.5f * r[2]));
        for (int j = 0; j < bones.Length; j++)
        {
            Transform b = bones[j];
            if (b == null) continue;
            var rotation = new Quaternion(q[4 * j + 1], -q[4 * j + 2], -q[4 * j + 3], q[4 * j]);
            if (isRoot[j])
            {
                b.position = new Vector3(-x[3 * j], ground + x[3 * j + 1], x[3 * j + 2]);
                b.rotation = rotation;
            }
            else
            {
                b.localRotation = rotation;
            }
        }
    }

    void OnDestroy()
    {
        if (character != null) character.Dispose();
        if (controller != null) controller.Dispose();
        character = null;
        controller = null;
    }
}
