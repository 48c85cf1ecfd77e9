// MmrlRuntime.cs: a C# binding of the mmrl runtime's C interface (cpp/capi/mmrl_runtime.h),
// P/Invoke with SafeHandles, for Unity or any .NET / Mono program (docs/engines.md).
//
//   using (var controller = MmrlController.Load("plane.mmrl"))
//   using (var character = controller.CreateCharacter(0, 0, 0))
//   {
//       character.SetTarget(3, 4);          // world meters; or character.SetStick(0, 1, 1.4f): direction, m/s
//       var pose = new MmrlPose(controller.NumJoints);
//       character.Update(1f / 30f, pose);   // pose.LocalRotations (w, x, y, z per joint), pose.Root
//   }
//
// mmrl's frame: meters, radians, m/s; Y up, yaw 0 faces +Z, +X is the character's left
// (right-handed, as BVH). Unity's is left-handed: unity/MmrlCharacterBehaviour.cs converts.
//
// Every failing call throws MmrlException with the status and the library's message. The
// library is found as "mmrl_runtime_c" (libmmrl_runtime_c.so, mmrl_runtime_c.dll,
// libmmrl_runtime_c.dylib): put it beside the program, in LD_LIBRARY_PATH, or in Unity's
// Assets/Plugins.
using System;
using System.Runtime.InteropServices;
using System.Text;

namespace Mmrl
{
    public enum MmrlStatus
    {
        Ok = 0,
        InvalidArgument = 1,
        File = 2,
        Version = 3,
        Null = 4,
        BufferTooSmall = 5,
        Internal = 6,
    }

    public sealed class MmrlException : Exception
    {
        public MmrlStatus Status { get; }

        public MmrlException(MmrlStatus status, string message) : base(message) { Status = status; }
    }

    [StructLayout(LayoutKind.Sequential)]
    public struct MmrlDecision
    {
        public long Count;
        public long FramesBefore;
        public long Match;
        public int Transition;
        public float RootX, RootZ, RootYaw;
        public float TargetX, TargetZ;
        public float Cost;
    }

    internal static class Native
    {
        const string Lib = "mmrl_runtime_c";

        [DllImport(Lib)] public static extern int mmrl_api_version();
        [DllImport(Lib)] public static extern int mmrl_file_version();
        [DllImport(Lib)] public static extern IntPtr mmrl_last_error();
        [DllImport(Lib)] public static extern MmrlStatus mmrl_controller_load(
            [MarshalAs(UnmanagedType.LPUTF8Str)] string path, out ControllerHandle controller);
        [DllImport(Lib)] public static extern MmrlStatus mmrl_controller_load_memory(
            byte[] data, UIntPtr size, [MarshalAs(UnmanagedType.LPUTF8Str)] string name, out ControllerHandle controller);
        [DllImport(Lib)] public static extern void mmrl_controller_destroy(IntPtr controller);
        [DllImport(Lib)] public static extern IntPtr mmrl_controller_last_error(ControllerHandle controller);
        [DllImport(Lib)] public static extern MmrlStatus mmrl_controller_num_joints(ControllerHandle controller, out int n);
        [DllImport(Lib)] public static extern MmrlStatus mmrl_controller_joint_name(
            ControllerHandle controller, int joint, byte[] buffer, UIntPtr size, out UIntPtr needed);
        [DllImport(Lib)] public static extern MmrlStatus mmrl_controller_joint_parent(ControllerHandle controller, int joint, out int parent);
        [DllImport(Lib)] public static extern MmrlStatus mmrl_controller_fps(ControllerHandle controller, out float fps);
        [DllImport(Lib)] public static extern MmrlStatus mmrl_controller_frames_per_step(ControllerHandle controller, out int n);
        [DllImport(Lib)] public static extern MmrlStatus mmrl_controller_success_radius(ControllerHandle controller, out float r);
        [DllImport(Lib)] public static extern MmrlStatus mmrl_controller_num_start_frames(ControllerHandle controller, out long n);
        [DllImport(Lib)] public static extern MmrlStatus mmrl_controller_start_frame(ControllerHandle controller, long k, out long frame);
        [DllImport(Lib)] public static extern MmrlStatus mmrl_character_create(
            ControllerHandle controller, float x, float z, float yaw, long startFrame, out CharacterHandle character);
        [DllImport(Lib)] public static extern void mmrl_character_destroy(IntPtr character);
        [DllImport(Lib)] public static extern IntPtr mmrl_character_last_error(CharacterHandle character);
        [DllImport(Lib)] public static extern MmrlStatus mmrl_character_set_target(CharacterHandle character, float x, float z);
        [DllImport(Lib)] public static extern MmrlStatus mmrl_character_set_facing(CharacterHandle character, float yaw);
        [DllImport(Lib)] public static extern MmrlStatus mmrl_character_set_stick(CharacterHandle character, float x, float z, float speed);
        [DllImport(Lib)] public static extern MmrlStatus mmrl_character_set_request(
            CharacterHandle character, [MarshalAs(UnmanagedType.LPUTF8Str)] string request);
        [DllImport(Lib)] public static extern MmrlStatus mmrl_character_set_obstacles(
            CharacterHandle character, int n, float[] centres, float[] halfSizes, float[] angles, float[] velocities);
        [DllImport(Lib)] public static extern MmrlStatus mmrl_character_update(
            CharacterHandle character, float dt, float[] localRotations, float[] localTranslations, int capacity, float[] root);
        [DllImport(Lib)] public static extern MmrlStatus mmrl_character_root(CharacterHandle character, float[] root);
        [DllImport(Lib)] public static extern MmrlStatus mmrl_character_last_decision(CharacterHandle character, out MmrlDecision decision);

        public static string Text(IntPtr utf8)
        {
            if (utf8 == IntPtr.Zero) return "";
            int n = 0;
            while (Marshal.ReadByte(utf8, n) != 0) n++;
            var bytes = new byte[n];
            Marshal.Copy(utf8, bytes, 0, n);
            return Encoding.UTF8.GetString(bytes);
        }
    }

    public sealed class ControllerHandle : SafeHandle
    {
        public ControllerHandle() : base(IntPtr.Zero, true) { }
        public override bool IsInvalid => handle == IntPtr.Zero;
        protected override bool ReleaseHandle() { Native.mmrl_controller_destroy(handle); return true; }
    }

    public sealed class CharacterHandle : SafeHandle
    {
        public CharacterHandle() : base(IntPtr.Zero, true) { }
        public override bool IsInvalid => handle == IntPtr.Zero;
        protected override bool ReleaseHandle() { Native.mmrl_character_destroy(handle); return true; }
    }

    /// <summary>The pose a character shows: caller-owned arrays the library writes into.</summary>
    public sealed class MmrlPose
    {
        public readonly float[] LocalRotations;     // joints x 4 (w, x, y, z)
        public readonly float[] LocalTranslations;  // joints x 3, meters
        public readonly float[] Root = new float[3]; // world x, z, yaw (radians)
        public int Capacity => LocalRotations.Length / 4;

        public MmrlPose(int joints)
        {
            LocalRotations = new float[joints * 4];
            LocalTranslations = new float[joints * 3];
        }
    }

    public sealed class MmrlController : IDisposable
    {
        internal readonly ControllerHandle Handle;

        MmrlController(ControllerHandle h) { Handle = h; }

        public static int ApiVersion => Native.mmrl_api_version();
        public static int FileVersion => Native.mmrl_file_version();

        public static MmrlController Load(string path)
        {
            var status = Native.mmrl_controller_load(path, out var h);
            if (status != MmrlStatus.Ok) throw new MmrlException(status, Native.Text(Native.mmrl_last_error()));
            return new MmrlController(h);
        }

        public static MmrlController Load(byte[] data, string name = "<memory>")
        {
            var status = Native.mmrl_controller_load_memory(data, (UIntPtr)data.Length, name, out var h);
            if (status != MmrlStatus.Ok) throw new MmrlException(status, Native.Text(Native.mmrl_last_error()));
            return new MmrlController(h);
        }

        internal void Check(MmrlStatus status)
        {
            if (status != MmrlStatus.Ok) throw new MmrlException(status, Native.Text(Native.mmrl_controller_last_error(Handle)));
        }

        public int NumJoints { get { Check(Native.mmrl_controller_num_joints(Handle, out var n)); return n; } }
        public float Fps { get { Check(Native.mmrl_controller_fps(Handle, out var f)); return f; } }
        public int FramesPerStep { get { Check(Native.mmrl_controller_frames_per_step(Handle, out var n)); return n; } }
        public float SuccessRadius { get { Check(Native.mmrl_controller_success_radius(Handle, out var r)); return r; } }

        public string JointName(int joint)
        {
            Native.mmrl_controller_joint_name(Handle, joint, null, UIntPtr.Zero, out var needed);
            var buffer = new byte[(int)needed.ToUInt64()];
            Check(Native.mmrl_controller_joint_name(Handle, joint, buffer, (UIntPtr)buffer.Length, out needed));
            return Encoding.UTF8.GetString(buffer, 0, buffer.Length - 1);
        }

        public long NumStartFrames { get { Check(Native.mmrl_controller_num_start_frames(Handle, out var n)); return n; } }
        public long StartFrame(long k) { Check(Native.mmrl_controller_start_frame(Handle, k, out var f)); return f; }

        public int JointParent(int joint) { Check(Native.mmrl_controller_joint_parent(Handle, joint, out var p)); return p; }

        /// <summary>A character at world (x, z), meters, facing yaw (radians; 0 faces +Z), on a
        /// database frame (-1: the first valid one).</summary>
        public MmrlCharacter CreateCharacter(float x, float z, float yaw, long startFrame = -1)
        {
            Check(Native.mmrl_character_create(Handle, x, z, yaw, startFrame, out var h));
            return new MmrlCharacter(h);
        }

        public void Dispose() => Handle.Dispose();
    }

    public sealed class MmrlCharacter : IDisposable
    {
        readonly CharacterHandle handle;

        internal MmrlCharacter(CharacterHandle h) { handle = h; }

        void Check(MmrlStatus status)
        {
            if (status != MmrlStatus.Ok) throw new MmrlException(status, Native.Text(Native.mmrl_character_last_error(handle)));
        }

        /// <summary>The target, world meters (mmrl's frame), from the next decision on; ends a stick.</summary>
        public void SetTarget(float x, float z) => Check(Native.mmrl_character_set_target(handle, x, z));

        /// <summary>The facing to arrive with (arrive controllers): a world yaw in RADIANS, mmrl's frame
        /// (0 faces +Z), from the next decision on. MmrlException (InvalidArgument) when not finite or when
        /// the controller's task reads no facing.</summary>
        public void SetFacing(float yaw) => Check(Native.mmrl_character_set_facing(handle, yaw));

        /// <summary>A stick in place of the target and the policy, from the next decision on: a world
        /// direction (x, z in mmrl's frame; any length > 0) and a speed in m/s (> 0). SetTarget ends it.
        /// MmrlException (InvalidArgument) for a zero or non-finite direction or a bad speed.</summary>
        public void SetStick(float x, float z, float speed) => Check(Native.mmrl_character_set_stick(handle, x, z, speed));
        public void SetRequest(string request) => Check(Native.mmrl_character_set_request(handle, request ?? ""));

        public void SetObstacles(int n, float[] centres, float[] halfSizes, float[] angles, float[] velocities = null)
            => Check(Native.mmrl_character_set_obstacles(handle, n, centres, halfSizes, angles, velocities));

        public void Update(float dt, MmrlPose pose)
            => Check(Native.mmrl_character_update(handle, dt, pose.LocalRotations, pose.LocalTranslations, pose.Capacity, pose.Root));

        public float[] Root { get { var r = new float[3]; Check(Native.mmrl_character_root(handle, r)); return r; } }

        public MmrlDecision LastDecision { get { Check(Native.mmrl_character_last_decision(handle, out var d)); return d; } }

        public void Dispose() => handle.Dispose();
    }
}
