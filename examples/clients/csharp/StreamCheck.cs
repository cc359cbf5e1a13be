// CompactStreamClient (InbetweenStream.cs) against a real server, as a game
// loop would drive it: uploads a clip (a new version of the clip of its name), opens its compact stream at 30 fps,
// takes the newest frame every few milliseconds, seeks half-way after 10
// frames, stops after --frames, and exits non-zero when
// - a decoded pose is further from the server's own pose (REST, local space, at
//   the frame's clip time) than the layout's max_error (or its bound, when even
//   24 bits cannot meet max_error), measured as
//   docs/compact-frames.md states the bound: each joint's model-space origin and
//   its three points at `distance` along its axes;
// - a frame before the seek breaks the schedule, or the seek never shows;
// - the stream does not close 1000 after the stop.
// CLIP is a clip document (.json) or a glTF, GLB or BVH file to import (its
// first clip). Run by scripts/clients.sh:
//
//   mcs -out:check.exe Compact.cs InbetweenStream.cs StreamCheck.cs
//   mono check.exe --http http://127.0.0.1:8080 examples/wave.json

using System;
using System.Collections.Generic;
using System.Globalization;
using System.IO;
using System.Net;
using System.Net.WebSockets;
using System.Text;
using System.Threading;

using Inbetween;

static class StreamCheck
{
    const int Fps = 30;
    static string http = "http://127.0.0.1:8080";
    static string token;

    static int Main(string[] args)
    {
        int frames = 60;
        string file = null;
        for (int i = 0; i < args.Length; i++)
        {
            if (args[i] == "--http") http = args[++i].TrimEnd('/');
            else if (args[i] == "--token") token = args[++i];
            else if (args[i] == "--frames") frames = int.Parse(args[++i], CultureInfo.InvariantCulture);
            else file = args[i];
        }
        if (file == null)
        {
            Console.Error.WriteLine("usage: StreamCheck.exe [--http URL] [--token T] [--frames N] CLIP.json");
            return 2;
        }
        try
        {
            Run(file, frames);
            return 0;
        }
        catch (Exception e)
        {
            Console.Error.WriteLine("FAIL: " + e.Message);
            return 1;
        }
    }

    static void Run(string file, int wanted)
    {
        var created = Upload(file);
        var id = (string)created["id"];
        double start = (double)created["start"], duration = (double)created["duration"];
        var parents = Parents(Object(Request("GET", "/v1/clips/" + id, null, null)));
        var ws = "ws" + http.Substring(http.IndexOf(':'));
        var uri = new Uri(CompactStreamClient.ClipUri(ws, id, Fps, 0, 0) + "&playback=loop");
        using (var client = new CompactStreamClient(uri, token))
        {
            client.Start();
            var decoder = WaitFor(() => client.Decoder, client, "the opened message");
            var layout = decoder.Layout;
            var frame = decoder.NewFrame();
            int[] parent = ParentIndices(decoder.Names, parents);
            double seekTo = start + duration / 2, worst = 0;
            // max_error, or the layout's bound when even 24 bits cannot meet max_error.
            double promised = Math.Max(layout.MaxError, layout.Bound);
            long? seekSeq = null, landed = null;
            int taken = 0;
            while (taken < wanted)
            {
                if (!WaitForFrame(client, frame)) throw new Exception("no frame for 5 s: " + (client.Error ?? "the stream ended"));
                taken++;
                if (seekSeq == null)
                {
                    double expected = start + (frame.Seq / (double)Fps) % duration;
                    Check(Math.Abs(frame.ClipTime - expected) < 1e-4, "seq " + frame.Seq + ": clip time " + frame.ClipTime + ", expected " + expected);
                }
                else if (landed == null && Math.Abs(frame.ClipTime - seekTo) < 0.5 / Fps + 1e-4)
                {
                    landed = (long)frame.Seq;
                }
                if (taken == 10)
                {
                    client.Send("{\"op\":\"seek\",\"time\":" + seekTo.ToString("R", CultureInfo.InvariantCulture) + "}");
                    seekSeq = (long)frame.Seq;
                }
                var pose = Object(Request("GET", "/v1/clips/" + id + "/pose?space=local&t=" + frame.ClipTime.ToString("R", CultureInfo.InvariantCulture), null, null));
                double error = PointError(frame, (List<object>)pose["joints"], parent, layout.Distance);
                Check(error <= promised, "seq " + frame.Seq + ": a point " + error + " m from the server's pose, over " + promised);
                worst = Math.Max(worst, error);
            }
            Check(landed != null, "the seek to " + seekTo + " never showed in the frames");
            client.Send("{\"op\":\"stop\"}");
            WaitFor(() => client.Finished ? "" : null, client, "the close after the stop");
            Check(client.CloseStatus == WebSocketCloseStatus.NormalClosure, "closed " + client.CloseStatus + " " + client.CloseDescription + " " + client.Error);
            Console.WriteLine(
                "C# compact stream: {0} joints, {1} frames decoded, {2} taken; seek landed on seq {3}; " +
                "worst point error {4:E2} m (max_error {5:E2}, bound {6:E2}); closed 1000 {7}",
                decoder.JointCount, client.FramesDecoded, taken, landed, worst, layout.MaxError, layout.Bound, client.CloseDescription);
        }
    }

    // ---- the bound (docs/compact-frames.md, "The error bound") ----

    // The largest distance between the decoded pose's and the server's pose's model-space points: each joint's
    // origin and its points at `distance` along x, y and z.
    static double PointError(CompactFrame frame, List<object> joints, int[] parent, double distance)
    {
        int n = parent.Length;
        Check(joints.Count == n, joints.Count + " joints in the REST pose, " + n + " in the stream");
        var decoded = new double[n][];
        var served = new double[n][];
        double worst = 0;
        for (int j = 0; j < n; j++)
        {
            var joint = (Dictionary<string, object>)joints[j];
            decoded[j] = Model(parent[j] < 0 ? null : decoded[parent[j]],
                Local(frame.Translations, 3 * j, 3), Local(frame.Rotations, 4 * j, 4), Local(frame.Scales, 3 * j, 3));
            served[j] = Model(parent[j] < 0 ? null : served[parent[j]],
                Numbers(joint["translation"]), Numbers(joint["rotation"]), Numbers(joint["scale"]));
            for (int axis = -1; axis < 3; axis++)
            {
                var p = new double[3];
                if (axis >= 0) p[axis] = distance;
                worst = Math.Max(worst, Distance(Apply(decoded[j], p), Apply(served[j], p)));
            }
        }
        return worst;
    }

    static double[] Local(float[] values, int at, int count)
    {
        var v = new double[count];
        for (int k = 0; k < count; k++) v[k] = values[at + k];
        return v;
    }

    static double[] Numbers(object list)
    {
        var l = (List<object>)list;
        var v = new double[l.Count];
        for (int k = 0; k < l.Count; k++) v[k] = (double)l[k];
        return v;
    }

    // A 3x4 affine matrix (row-major) of parent · T · R · S.
    static double[] Model(double[] parentMatrix, double[] t, double[] q, double[] s)
    {
        double x = q[0], y = q[1], z = q[2], w = q[3];
        var r = new[]
        {
            1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w),
            2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w),
            2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y),
        };
        var local = new double[12];
        for (int row = 0; row < 3; row++)
        {
            for (int col = 0; col < 3; col++) local[4 * row + col] = r[3 * row + col] * s[col];
            local[4 * row + 3] = t[row];
        }
        if (parentMatrix == null) return local;
        var m = new double[12];
        for (int row = 0; row < 3; row++)
        {
            for (int col = 0; col < 4; col++)
            {
                double sum = col == 3 ? parentMatrix[4 * row + 3] : 0;
                for (int k = 0; k < 3; k++) sum += parentMatrix[4 * row + k] * local[4 * k + col];
                m[4 * row + col] = sum;
            }
        }
        return m;
    }

    static double[] Apply(double[] m, double[] p)
    {
        var o = new double[3];
        for (int row = 0; row < 3; row++) o[row] = m[4 * row] * p[0] + m[4 * row + 1] * p[1] + m[4 * row + 2] * p[2] + m[4 * row + 3];
        return o;
    }

    static double Distance(double[] a, double[] b)
    {
        return Math.Sqrt((a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]) + (a[2] - b[2]) * (a[2] - b[2]));
    }

    // A clip document (.json), or the first clip of a glTF, GLB or BVH file (docs/import.md); a new version of the
    // clip of its name either way.
    static Dictionary<string, object> Upload(string file)
    {
        if (file.EndsWith(".json", StringComparison.OrdinalIgnoreCase))
        {
            return Object(Request("POST", "/v1/clips?replace=true", Encoding.UTF8.GetBytes(File.ReadAllText(file)), "application/json"));
        }
        var imported = Object(Request("POST", "/v1/clips/import?replace=true", File.ReadAllBytes(file), "application/octet-stream"));
        return (Dictionary<string, object>)((List<object>)imported["clips"])[0];
    }

    // ---- the clip's skeleton ----

    static Dictionary<string, string> Parents(Dictionary<string, object> clip)
    {
        var parents = new Dictionary<string, string>();
        foreach (Dictionary<string, object> joint in (List<object>)((Dictionary<string, object>)clip["skeleton"])["joints"])
        {
            object parent;
            joint.TryGetValue("parent", out parent);
            parents[(string)joint["name"]] = parent as string;
        }
        return parents;
    }

    static int[] ParentIndices(string[] names, Dictionary<string, string> parents)
    {
        var index = new Dictionary<string, int>();
        var parent = new int[names.Length];
        for (int j = 0; j < names.Length; j++)
        {
            var p = parents[names[j]];
            parent[j] = p == null ? -1 : index[p]; // parents come first (docs/compact-frames.md, "The layout document")
            index[names[j]] = j;
        }
        return parent;
    }

    // ---- plumbing ----

    static T WaitFor<T>(Func<T> poll, CompactStreamClient client, string what) where T : class
    {
        var deadline = DateTime.UtcNow.AddSeconds(10);
        while (DateTime.UtcNow < deadline)
        {
            var value = poll();
            if (value != null) return value;
            Thread.Sleep(2);
        }
        throw new Exception("no " + what + " within 10 s: " + (client.Error ?? "nothing went wrong that the client saw"));
    }

    // A game's frame loop, at a few milliseconds a turn.
    static bool WaitForFrame(CompactStreamClient client, CompactFrame frame)
    {
        var deadline = DateTime.UtcNow.AddSeconds(5);
        while (DateTime.UtcNow < deadline)
        {
            if (client.TryTakeNewest(frame)) return true;
            if (client.Finished) return false;
            Thread.Sleep(3);
        }
        return false;
    }

    static string Request(string method, string path, byte[] body, string type)
    {
        var request = (HttpWebRequest)WebRequest.Create(http + path);
        request.Method = method;
        if (token != null) request.Headers["Authorization"] = "Bearer " + token;
        if (body != null)
        {
            request.ContentType = type;
            using (var stream = request.GetRequestStream()) stream.Write(body, 0, body.Length);
        }
        try
        {
            using (var response = (HttpWebResponse)request.GetResponse())
            using (var reader = new StreamReader(response.GetResponseStream())) return reader.ReadToEnd();
        }
        catch (WebException e)
        {
            var response = e.Response as HttpWebResponse;
            if (response == null) throw;
            using (var reader = new StreamReader(response.GetResponseStream()))
            {
                throw new Exception(method + " " + path + ": " + (int)response.StatusCode + " " + reader.ReadToEnd());
            }
        }
    }

    static Dictionary<string, object> Object(string json)
    {
        return (Dictionary<string, object>)CompactJson.Parse(json);
    }

    static void Check(bool ok, string what)
    {
        if (!ok) throw new Exception(what);
    }
}
