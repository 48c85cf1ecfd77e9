// Small stand-ins of the UnityEngine types MmrlCharacterBehaviour.cs uses, so that the guide's
// script compiles (and runs, in tests/test_csharp.py) with Mono where Unity cannot run. Not for
// Unity itself: Unity brings the real ones. Only what the script touches, with Unity's semantics
// for it (a Transform hierarchy with names, local and world position and rotation; unit scale).
using System;
using System.Collections.Generic;

namespace UnityEngine
{
    [AttributeUsage(AttributeTargets.Field)]
    public sealed class SerializeField : Attribute { }

    public struct Vector2
    {
        public float x, y;
        public Vector2(float x, float y) { this.x = x; this.y = y; }
        public static Vector2 zero => new Vector2(0f, 0f);
    }

    public struct Vector3
    {
        public float x, y, z;
        public Vector3(float x, float y, float z) { this.x = x; this.y = y; this.z = z; }
        public static Vector3 forward => new Vector3(0f, 0f, 1f);
        public static Vector3 operator +(Vector3 a, Vector3 b) => new Vector3(a.x + b.x, a.y + b.y, a.z + b.z);
        public static Vector3 operator -(Vector3 a, Vector3 b) => new Vector3(a.x - b.x, a.y - b.y, a.z - b.z);
    }

    public struct Quaternion
    {
        public float x, y, z, w;
        public Quaternion(float x, float y, float z, float w) { this.x = x; this.y = y; this.z = z; this.w = w; }
        public static Quaternion identity => new Quaternion(0f, 0f, 0f, 1f);
        public static Quaternion Inverse(Quaternion q) => new Quaternion(-q.x, -q.y, -q.z, q.w);  // unit quaternions
        public static Quaternion operator *(Quaternion a, Quaternion b) => new Quaternion(
            a.w * b.x + a.x * b.w + a.y * b.z - a.z * b.y,
            a.w * b.y - a.x * b.z + a.y * b.w + a.z * b.x,
            a.w * b.z + a.x * b.y - a.y * b.x + a.z * b.w,
            a.w * b.w - a.x * b.x - a.y * b.y - a.z * b.z);
        public static Vector3 operator *(Quaternion q, Vector3 v)
        {
            var r = q * new Quaternion(v.x, v.y, v.z, 0f) * Inverse(q);
            return new Vector3(r.x, r.y, r.z);
        }
    }

    public static class Mathf
    {
        public static float Min(float a, float b) => a < b ? a : b;
        public static float Sin(float a) => (float)Math.Sin(a);
        public static float Cos(float a) => (float)Math.Cos(a);
        public static float Atan2(float y, float x) => (float)Math.Atan2(y, x);
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
        public Vector3 localPosition;
        public Quaternion localRotation = Quaternion.identity;

        // World position and rotation through the parents (unit scale).
        public Vector3 position
        {
            get => parent == null ? localPosition : parent.position + parent.rotation * localPosition;
            set => localPosition = parent == null ? value : Quaternion.Inverse(parent.rotation) * (value - parent.position);
        }
        public Quaternion rotation
        {
            get => parent == null ? localRotation : parent.rotation * localRotation;
            set => localRotation = parent == null ? value : Quaternion.Inverse(parent.rotation) * value;
        }
        public Vector3 forward => rotation * Vector3.forward;

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
