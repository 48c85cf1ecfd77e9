// Small stand-ins of the UnityEngine types MmrlCharacterBehaviour.cs uses, so that the guide's
// script compiles (and runs, in tests/test_csharp.py) with Mono where Unity cannot run. Not for
// Unity itself: Unity brings the real ones. Only what the script touches, with Unity's semantics
// for it (a Transform hierarchy with names, local position and rotation).
using System;
using System.Collections.Generic;

namespace UnityEngine
{
    [AttributeUsage(AttributeTargets.Field)]
    public sealed class SerializeField : Attribute { }

    public struct Vector3
    {
        public float x, y, z;
        public Vector3(float x, float y, float z) { this.x = x; this.y = y; this.z = z; }
    }

    public struct Quaternion
    {
        public float x, y, z, w;
        public Quaternion(float x, float y, float z, float w) { this.x = x; this.y = y; this.z = z; this.w = w; }
    }

    public static class Mathf
    {
        public static float Min(float a, float b) => a < b ? a : b;
    }

    public static class Time
    {
        public static float deltaTime = 1f / 30f;
    }

    public static class Application
    {
        public static string streamingAssetsPath = ".";
    }

    public static class Debug
    {
        public static readonly List<string> Warnings = new List<string>();
        public static void LogWarning(string message) => Warnings.Add(message);
    }

    public class Component
    {
        public Transform transform;
    }

    public class Transform : Component
    {
        public string name;
        public Transform parent;
        public readonly List<Transform> children = new List<Transform>();
        public Vector3 position;
        public Vector3 localPosition;
        public Quaternion localRotation = new Quaternion(0, 0, 0, 1);

        public Transform(string name, Transform parent = null)
        {
            this.name = name;
            this.parent = parent;
            transform = this;
            if (parent != null) parent.children.Add(this);
        }

        public T[] GetComponentsInChildren<T>() where T : Transform
        {
            var all = new List<T>();
            var stack = new Stack<Transform>();
            stack.Push(this);
            while (stack.Count > 0)
            {
                var t = stack.Pop();
                all.Add((T)t);
                for (int k = t.children.Count - 1; k >= 0; k--) stack.Push(t.children[k]);
            }
            return all.ToArray();
        }
    }

    public class MonoBehaviour : Component { }
}
