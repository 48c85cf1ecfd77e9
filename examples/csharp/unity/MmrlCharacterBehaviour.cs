// MmrlCharacterBehaviour.cs: a Unity MonoBehaviour that drives a character's Transform hierarchy
// with an exported mmrl controller (docs/engines.md). Put MmrlRuntime.cs beside it, the library
// (libmmrl_runtime_c.so / mmrl_runtime_c.dll) in Assets/Plugins, and the controller file in
// Assets/StreamingAssets.
//
// mmrl's world is right-handed with Y up (BVH); Unity's is left-handed with Y up. The pose is
// mirrored through the YZ plane on the way in: a position (x, y, z) becomes (-x, y, z), a
// rotation (w, x, y, z) becomes (w, x, -y, -z).
using System.Collections.Generic;
using System.IO;
using Mmrl;
using UnityEngine;

public class MmrlCharacterBehaviour : MonoBehaviour
{
    [SerializeField] string controllerFile = "plane.mmrl";   // in Assets/StreamingAssets
    [SerializeField] Transform target;                        // where the character should go
    [SerializeField] Transform skeletonRoot;                  // the rig's root bone (default: this object)
    [SerializeField] string request = "";                     // e.g. "style=elderly" (docs/styles.md)

    MmrlController controller;
    MmrlCharacter character;
    MmrlPose pose;
    Transform[] bones;   // per mmrl joint, the rig's transform of the same name (null if missing)
    string appliedRequest = "";

    void Start()
    {
        controller = MmrlController.Load(Path.Combine(Application.streamingAssetsPath, controllerFile));
        Vector3 p = transform.position;
        character = controller.CreateCharacter(-p.x, p.z, 0f);
        pose = new MmrlPose(controller.NumJoints);
        var byName = new Dictionary<string, Transform>();
        foreach (Transform t in (skeletonRoot != null ? skeletonRoot : transform).GetComponentsInChildren<Transform>())
            byName[t.name] = t;
        bones = new Transform[controller.NumJoints];
        for (int j = 0; j < bones.Length; j++)
        {
            Transform t;
            if (!byName.TryGetValue(controller.JointName(j), out t))
                Debug.LogWarning("mmrl: no transform named " + controller.JointName(j));
            bones[j] = t;
        }
    }

    void Update()
    {
        if (character == null) return;
        if (request != appliedRequest)
        {
            character.SetRequest(request);   // MmrlException lists the tags the file has
            appliedRequest = request;
        }
        if (target != null)
        {
            Vector3 t = target.position;
            character.SetTarget(-t.x, t.z);
        }
        character.Update(Mathf.Min(Time.deltaTime, 1f), pose);
        for (int j = 0; j < bones.Length; j++)
        {
            Transform b = bones[j];
            if (b == null) continue;
            float[] q = pose.LocalRotations, x = pose.LocalTranslations;
            b.localRotation = new Quaternion(q[4 * j + 1], -q[4 * j + 2], -q[4 * j + 3], q[4 * j]);
            if (controller.JointParent(j) < 0)
                b.localPosition = new Vector3(-x[3 * j], x[3 * j + 1], x[3 * j + 2]);
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
