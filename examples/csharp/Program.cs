// mmrl_trace: the C# twin of examples/runtime (mmrl_runtime_example): drive N characters with an
// exported controller through a scripted list of targets, through the C interface only, and write
// the same JSON trace (one line per decision step, per character):
//   {"character": i, "t": seconds, "root": [x, z, yaw], "target": [x, z], "frame": match, "transition": bool}
// Character i starts on start frame (i * 97) mod (start frames) at (2 * (i % 8), 2 * (i / 8))
// facing +Z and walks to its start + each target in turn (the next once within the success radius).
//
// usage: mono mmrl_trace.exe CONTROLLER [--characters N] [--decisions D] [--targets "x,z;x,z"] [--trace FILE]
//                                       [--request TAGS]
using System;
using System.Collections.Generic;
using System.Globalization;
using System.IO;
using Mmrl;

static class Program
{
    static int Main(string[] args)
    {
        try { return Run(args); }
        catch (Exception e) when (e is MmrlException || e is ArgumentException || e is FormatException || e is IOException)
        {
            Console.Error.WriteLine("mmrl_trace: error: " + e.Message);
            return 2;
        }
    }

    static List<float[]> ParseTargets(string text)
    {
        var list = new List<float[]>();
        foreach (var item in text.Split(';'))
        {
            var xz = item.Split(',');
            if (xz.Length != 2) throw new ArgumentException("--targets: expected \"x,z;x,z;...\", got \"" + item + "\"");
            list.Add(new[] { float.Parse(xz[0], CultureInfo.InvariantCulture), float.Parse(xz[1], CultureInfo.InvariantCulture) });
        }
        return list;
    }

    static string Fmt(double v, int digits) => v.ToString("F" + digits, CultureInfo.InvariantCulture);

    static string Value(string[] args, ref int k)
    {
        if (k + 1 >= args.Length) throw new ArgumentException(args[k] + " needs a value");
        return args[++k];
    }

    static int Run(string[] args)
    {
        string path = null, tracePath = null, request = null;
        int characters = 1;
        long decisions = 100;
        var targets = new List<float[]> { new[] { 0f, 4f }, new[] { 4f, 4f }, new[] { 4f, -2f }, new[] { -3f, 0f } };
        for (int k = 0; k < args.Length; k++)
        {
            switch (args[k])
            {
                case "--characters": characters = int.Parse(Value(args, ref k), CultureInfo.InvariantCulture); break;
                case "--decisions": decisions = long.Parse(Value(args, ref k), CultureInfo.InvariantCulture); break;
                case "--targets": targets = ParseTargets(Value(args, ref k)); break;
                case "--trace": tracePath = Value(args, ref k); break;
                case "--request": request = Value(args, ref k); break;
                default:
                    if (args[k].StartsWith("-")) throw new ArgumentException("unknown option " + args[k]);
                    path = args[k];
                    break;
            }
        }
        if (path == null) throw new ArgumentException("usage: mmrl_trace.exe CONTROLLER [options]");
        using (var controller = MmrlController.Load(path))
        {
            int F = controller.FramesPerStep;
            float dt = 1f / controller.Fps, radius = controller.SuccessRadius;
            long starts = controller.NumStartFrames;
            var chars = new List<MmrlCharacter>();
            var origin = new List<float[]>();
            var next = new int[characters];
            var pose = new MmrlPose(controller.NumJoints);
            for (int i = 0; i < characters; i++)
            {
                origin.Add(new[] { 2f * (i % 8), 2f * (i / 8) });
                var c = controller.CreateCharacter(origin[i][0], origin[i][1], 0f, controller.StartFrame((i * 97L) % starts));
                c.SetTarget(origin[i][0] + targets[0][0], origin[i][1] + targets[0][1]);
                if (!string.IsNullOrEmpty(request)) c.SetRequest(request);
                chars.Add(c);
            }
            using (var trace = tracePath == null ? null : new StreamWriter(tracePath) { NewLine = "\n" })
            {
                for (long step = 0; step < decisions; step++)
                {
                    for (int i = 0; i < characters; i++)
                    {
                        var c = chars[i];
                        var r = c.Root;
                        var tg = targets[next[i] % targets.Count];
                        double dx = origin[i][0] + tg[0] - r[0], dz = origin[i][1] + tg[1] - r[1];
                        if (Math.Sqrt(dx * dx + dz * dz) < radius)
                        {
                            var nt = targets[++next[i] % targets.Count];
                            c.SetTarget(origin[i][0] + nt[0], origin[i][1] + nt[1]);
                        }
                        for (int k = 0; k < F; k++) c.Update(dt, pose);
                        if (trace != null)
                        {
                            var d = c.LastDecision;
                            trace.WriteLine("{\"character\": " + i + ", \"t\": " + Fmt(d.FramesBefore / (double)controller.Fps, 4) +
                                            ", \"root\": [" + Fmt(d.RootX, 5) + ", " + Fmt(d.RootZ, 5) + ", " + Fmt(d.RootYaw, 5) +
                                            "], \"target\": [" + Fmt(d.TargetX, 5) + ", " + Fmt(d.TargetZ, 5) + "], \"frame\": " +
                                            d.Match + ", \"transition\": " + (d.Transition != 0 ? "true" : "false") + "}");
                        }
                    }
                }
            }
            foreach (var c in chars) c.Dispose();
        }
        return 0;
    }
}
