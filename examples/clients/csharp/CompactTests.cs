// The C# compact-frame decoder against docs/compact-frames/: every frame of
// every vector decodes to exactly the pose the Rust encoder quantised (the
// same checks as examples/clients/js/tests/compact.test.mjs), and malformed
// frames and layouts throw CompactException with its code, never an index
// error. Run: examples/clients/csharp/run-tests.sh

using System;
using System.Collections.Generic;
using System.Globalization;
using System.IO;
using System.Linq;

using Inbetween;

static class CompactTests
{
    static string vectorsDir;
    static int failures;
    static int passes;

    static int Main(string[] args)
    {
        vectorsDir = args.Length > 0 ? args[0] : Path.Combine("docs", "compact-frames");
        Run("there are vectors to read", ThereAreVectors);
        foreach (var vector in Vectors())
        {
            var v = vector;
            Run(Name(v) + ": every frame decodes to the stored pose exactly", () => DecodesExactly(v));
            Run(Name(v) + ": every prefix of every frame is refused compact_truncated", () => PrefixesAreTruncated(v));
            Run(Name(v) + ": a frame read from the middle of a larger buffer", () => DecodesAtAnOffset(v));
        }
        Run("the worked example decodes to the hand-computed rotation", WorkedExample);
        Run("a delta frame without its key frame is refused", MissingKeyFrame);
        Run("a new layout mid-stream forgets the old key frame", NewLayoutForgetsTheKeyFrame);
        Run("the stream client takes a new layout, names events and keeps root motion and graph reports", ClientTakesLayoutsEventsAndRootMotion);
        Run("root motion converts to Unity's axes", RootMotionConversion);
        Run("trailing bytes, unknown flags and overlong varints are refused", MalformedHeaders);
        Run("a refused frame changes neither the decoder nor the output", RefusedFrameChangesNothing);
        Run("random bytes decode or throw CompactException, nothing else", RandomBytes);
        Run("a layout of another version is refused compact_version", WrongVersion);
        Run("malformed layouts are refused compact_bad_layout at their JSON pointer", MalformedLayouts);
        Run("an opened message's layout is the vector's", OpenedMessage);
        Run("an event past the layout's list is refused", UnknownEvent);
        Run("the graph-report vector's reports name the layout's states and nodes", GraphReports);
        Run("a graph report's indices past the layout's graph and a report cut short are refused", GraphRefusals);
        Run("GltfToUnity and GltfToUnityMirrorZ are the mirrors of X and Z applied to the local transform", AxisConversionIsTheMirror);
        Console.WriteLine("{0} passed, {1} failed", passes, failures);
        return failures == 0 ? 0 : 1;
    }

    static void Run(string name, Action test)
    {
        try
        {
            test();
            passes++;
            Console.WriteLine("ok   " + name);
        }
        catch (Exception e)
        {
            failures++;
            Console.WriteLine("FAIL " + name + "\n     " + e.GetType().Name + ": " + e.Message);
        }
    }

    // ---- the vectors ----

    static List<Dictionary<string, object>> Vectors()
    {
        return Directory.GetFiles(vectorsDir, "*.json").OrderBy(f => f, StringComparer.Ordinal)
            .Select(f => (Dictionary<string, object>)CompactJson.Parse(File.ReadAllText(f))).ToList();
    }

    static Dictionary<string, object> Vector(string name)
    {
        return Vectors().First(v => Name(v) == name);
    }

    static string Name(Dictionary<string, object> v)
    {
        return (string)v["name"];
    }

    static CompactDecoder DecoderOf(Dictionary<string, object> vector)
    {
        return new CompactDecoder(CompactLayout.FromJson(vector["layout"]));
    }

    // A frame that comes first in a new layout mid-stream carries it (docs/compact-frames.md, "A new layout").
    static void NewLayout(CompactDecoder decoder, Dictionary<string, object> frame)
    {
        object layout;
        if (frame.TryGetValue("layout", out layout)) decoder.Relayout(CompactLayout.FromJson(layout));
    }

    static List<Dictionary<string, object>> Frames(Dictionary<string, object> vector)
    {
        return ((List<object>)vector["frames"]).Cast<Dictionary<string, object>>().ToList();
    }

    static byte[] Hex(Dictionary<string, object> frame)
    {
        var hex = (string)frame["hex"];
        var bytes = new byte[hex.Length / 2];
        for (int i = 0; i < bytes.Length; i++) bytes[i] = byte.Parse(hex.Substring(2 * i, 2), NumberStyles.HexNumber);
        return bytes;
    }

    // The pose's rows ([[x, y, z], …]) flattened and rounded to f32, as the JS test's Float32Array.from.
    static float[] Flat(Dictionary<string, object> frame, string name)
    {
        var pose = (Dictionary<string, object>)frame["pose"];
        return ((List<object>)pose[name]).Cast<List<object>>().SelectMany(row => row.Select(x => (float)(double)x)).ToArray();
    }

    // ---- the checks ----

    static void ThereAreVectors()
    {
        int count = Vectors().Count;
        Check(count >= 5, count + " vectors in " + vectorsDir);
    }

    static void DecodesExactly(Dictionary<string, object> vector)
    {
        var decoder = DecoderOf(vector);
        var got = decoder.NewFrame();
        foreach (var frame in Frames(vector))
        {
            NewLayout(decoder, frame);
            decoder.Decode(Hex(frame), got);
            CheckHeader(got, frame);
            var at = " (seq " + got.Seq + ")";
            SameBits(got.Rotations, Flat(frame, "rotations"), "rotations" + at);
            SameBits(got.Translations, Flat(frame, "translations"), "translations" + at);
            SameBits(got.Scales, Flat(frame, "scales"), "scales" + at);
            CheckTrailer(got, frame, at);
            CheckGraph(got, frame, at);
        }
    }

    // The frame's events (indices into the layout's list) and root motion, as the vector states them.
    static void CheckTrailer(CompactFrame got, Dictionary<string, object> frame, string at)
    {
        object events;
        var expected = frame.TryGetValue("events", out events) ? ((List<object>)events).Select(i => (int)(double)i).ToArray() : new int[0];
        Check(got.Events.Take(got.EventCount).SequenceEqual(expected), "events" + at);
        object root;
        Equal(frame.TryGetValue("root_motion", out root), got.HasRootMotion, "has root motion" + at);
        if (!got.HasRootMotion) return;
        var r = (Dictionary<string, object>)root;
        var values = ((List<object>)r["delta"]).Concat((List<object>)r["total"]).Select(x => (float)(double)x).ToArray();
        SameBits(got.RootMotion, values, "root motion" + at);
    }

    // The frame's graph report (indices into the layout's graph, numbers rounded to f32), as the vector states it.
    static void CheckGraph(CompactFrame got, Dictionary<string, object> frame, string at)
    {
        object graph;
        Equal(frame.TryGetValue("graph", out graph), got.HasGraph, "has a graph report" + at);
        Equal(got.HasGraph, got.Graph != null, "Graph is set exactly when HasGraph" + at);
        if (!got.HasGraph) return;
        var want = (Dictionary<string, object>)graph;
        Equal((int)(double)want["state"], got.Graph.State, "state" + at);
        var transition = want["transition"] as Dictionary<string, object>;
        Equal(transition != null, got.Graph.HasTransition, "has a transition" + at);
        if (transition != null)
        {
            Equal((int)(double)transition["from"], got.Graph.Transition.From, "from" + at);
            Equal((int)(double)transition["to"], got.Graph.Transition.To, "to" + at);
            SameBits(new[] { got.Graph.Transition.Alpha }, new[] { (float)(double)transition["alpha"] }, "alpha" + at);
        }
        var nodes = ((List<object>)want["weights"]).Cast<Dictionary<string, object>>().ToList();
        Equal(nodes.Count, got.Graph.NodeCount, "nodes" + at);
        for (int i = 0; i < nodes.Count; i++)
        {
            Equal((int)(double)nodes[i]["node"], got.Graph.Nodes[i], "node " + i + at);
            var weights = ((List<object>)nodes[i]["weights"]).Select(x => (float)(double)x).ToArray();
            Equal(weights.Length, got.Graph.NodeWeights(i).Count, "node " + i + "'s weights" + at);
            SameBits(got.Graph.NodeWeights(i).ToArray(), weights, "node " + i + "'s weights" + at);
        }
    }

    static void CheckHeader(CompactFrame got, Dictionary<string, object> frame)
    {
        Equal((bool)frame["key"], got.Key, "key");
        Equal((ulong)(double)frame["seq"], got.Seq, "seq");
        Equal((ulong)(double)frame["dropped"], got.Dropped, "dropped");
        Equal(long.Parse((string)frame["sent_at_unix_nanos"], CultureInfo.InvariantCulture), got.SentAtUnixNanos, "sent_at_unix_nanos");
        SameBits(new[] { got.ClipTime }, new[] { (float)(double)frame["clip_time"] }, "clip_time");
    }

    static void PrefixesAreTruncated(Dictionary<string, object> vector)
    {
        var decoder = DecoderOf(vector);
        var got = decoder.NewFrame();
        foreach (var frame in Frames(vector))
        {
            NewLayout(decoder, frame);
            var bytes = Hex(frame);
            for (int n = 0; n < bytes.Length; n++)
            {
                Refused("compact_truncated", () => decoder.Decode(bytes, 0, n, got));
            }
            decoder.Decode(bytes, got); // the whole frame: the next delta frame's key frame is known
        }
    }

    static void DecodesAtAnOffset(Dictionary<string, object> vector)
    {
        var decoder = DecoderOf(vector);
        var got = decoder.NewFrame();
        foreach (var frame in Frames(vector))
        {
            NewLayout(decoder, frame);
            var bytes = Hex(frame);
            var buffer = new byte[bytes.Length + 7];
            for (int i = 0; i < buffer.Length; i++) buffer[i] = 0xff;
            Array.Copy(bytes, 0, buffer, 3, bytes.Length);
            decoder.Decode(buffer, 3, bytes.Length, got);
            CheckHeader(got, frame);
            SameBits(got.Rotations, Flat(frame, "rotations"), "rotations");
        }
    }

    // docs/compact-frames.md, "Worked example": half-turn's second frame, the joint's x in 9 bits = 460, y and z in
    // 10 bits = 512, w rebuilt; the values below are computed by hand from those fields (m = 0.70710677).
    static void WorkedExample()
    {
        var vector = Vector("half-turn");
        var decoder = DecoderOf(vector);
        var got = decoder.NewFrame();
        decoder.Decode(Hex(Frames(vector)[0]), got);
        decoder.Decode(Hex(Frames(vector)[1]), got);
        double m = (float)0.70710677;
        double x = -m + (460 * 2 * m) / 511;
        double y = -m + (512 * 2 * m) / 1023;
        double w = Math.Sqrt(1 - (x * x + y * y + y * y));
        var expected = new[] { (float)x, (float)y, (float)y, (float)w };
        SameBits(got.Rotations, expected, "rotation");
        Near(got.Rotations, new[] { 0.5659622f, 0.000691209f, 0.000691209f, 0.82443064f }, 1e-7, "the doc's rounded values");
        Equal(8UL, got.Seq, "seq");
        Equal(7UL, got.KeySeq, "key seq");
        Equal(1764680000050000000L, got.SentAtUnixNanos, "sent_at");
        Equal(0.4f, got.ClipTime, "clip_time");
        Equal(1, got.JointsSent, "joints sent");
    }

    static void MissingKeyFrame()
    {
        var vector = Vector("bench20");
        var decoder = DecoderOf(vector);
        var got = decoder.NewFrame();
        Refused("compact_missing_key_frame", () => decoder.Decode(Hex(Frames(vector)[1]), got));
        // A key frame, then a delta frame naming another key frame (its key offset one more).
        decoder.Decode(Hex(Frames(vector)[0]), got);
        var delta = Hex(Frames(vector)[1]);
        int offsetAt = 1 + VarintLength(delta, 1) + VarintLength(delta, 1 + VarintLength(delta, 1));
        Check(delta[offsetAt] < 0x7f, "a one-byte key offset");
        delta[offsetAt]++;
        Refused("compact_missing_key_frame", () => decoder.Decode(delta, got));
    }

    static void NewLayoutForgetsTheKeyFrame()
    {
        var vector = Vector("relayout");
        var frames = Frames(vector);
        var decoder = DecoderOf(vector);
        var got = decoder.NewFrame();
        decoder.Decode(Hex(frames[0]), got);
        decoder.Decode(Hex(frames[1]), got);
        NewLayout(decoder, frames[2]);
        Refused("compact_missing_key_frame", () => decoder.Decode(Hex(frames[3]), got));
        decoder.Decode(Hex(frames[2]), got);
        Check(got.Key, "the new layout's key frame");
        decoder.Decode(Hex(frames[3]), got);
        SameBits(got.Translations, Flat(frames[3], "translations"), "translations in the new layout");
    }

    // The layout objects of a vector's text, in the order they appear (the keys are sorted: a frame's new layout
    // comes before the vector's own).
    static List<string> LayoutTexts(string name)
    {
        var text = File.ReadAllText(Path.Combine(vectorsDir, name + ".json"));
        var found = new List<string>();
        for (int at = text.IndexOf("\"layout\": ", StringComparison.Ordinal); at >= 0; at = text.IndexOf("\"layout\": ", at + 1, StringComparison.Ordinal))
        {
            found.Add(ExtractObject(text, at + "\"layout\": ".Length));
        }
        return found;
    }

    // The stream client as its socket would feed it: the opened message, frames, a new layout mid-stream; the
    // newest frame with its root motion, and every event crossed, named by the layout it was decoded in.
    static void ClientTakesLayoutsEventsAndRootMotion()
    {
        var client = new CompactStreamClient(new Uri("ws://127.0.0.1:1/"), null);
        client.OnText("{\"opened\": {\"compact\": " + LayoutTexts("stepping")[0] + "}}");
        foreach (var frame in Frames(Vector("stepping")))
        {
            var bytes = Hex(frame);
            client.OnFrame(bytes, bytes.Length);
        }
        var events = new List<CrossedEvent>();
        Equal(3, client.TakeEvents(events), "events crossed");
        Equal("step_left@7 step_right@9 land@9", string.Join(" ", events.Select(e => e.Name + "@" + e.Seq)), "events");
        Equal(0, client.TakeEvents(events), "taken once");
        var got = client.Decoder.NewFrame();
        Check(client.TryTakeNewest(got), "a newest frame");
        Check(!got.HasRootMotion, "the last stepping frame reports none");
        client = new CompactStreamClient(new Uri("ws://127.0.0.1:1/"), null);
        client.OnText("{\"opened\": {\"compact\": " + LayoutTexts("graph-report")[0] + "}}");
        foreach (var frame in Frames(Vector("graph-report")))
        {
            var bytes = Hex(frame);
            client.OnFrame(bytes, bytes.Length);
        }
        Check(client.TryTakeNewest(got), "a newest graph frame");
        Equal("move - walkrun[0.5,0.5] aim[0.125,0.375,0.5]", Report(client.Decoder.Layout, got.Graph), "the newest frame's graph report");
        var relayout = Vector("relayout");
        var texts = LayoutTexts("relayout");
        client = new CompactStreamClient(new Uri("ws://127.0.0.1:1/"), null);
        client.OnText("{\"opened\": {\"compact\": " + texts[1] + "}}");
        var frames = Frames(relayout);
        for (int i = 0; i < frames.Count; i++)
        {
            if (i == 2) client.OnText("{\"layout\": " + texts[0] + ", \"seq\": 9}");
            var bytes = Hex(frames[i]);
            client.OnFrame(bytes, bytes.Length);
        }
        Equal(null, client.Error, "no error across the new layout");
        Check(client.TryTakeNewest(got), "the newest frame");
        SameBits(got.Translations, Flat(frames[3], "translations"), "the new layout's delta frame");
    }

    // Root motion as the MonoBehaviour puts it on its Transform: mirrored as a joint's translation, the yaw negated,
    // and the yaw turned before the placement.
    static void RootMotionConversion()
    {
        var m = new[] { 1f, 2f, 3f, 0.5f };
        UnityAxes.ConvertRootMotion(AxisConversion.GltfToUnity, m);
        Equal("-1 2 3 -0.5", string.Join(" ", m.Select(x => x.ToString(CultureInfo.InvariantCulture))), "mirror X");
        m = new[] { 1f, 2f, 3f, 0.5f };
        UnityAxes.ConvertRootMotion(AxisConversion.GltfToUnityMirrorZ, m);
        Equal("1 2 -3 -0.5", string.Join(" ", m.Select(x => x.ToString(CultureInfo.InvariantCulture))), "mirror Z");
        var q = UnityAxes.YawThen(1.0f, new[] { 0f, 0f, 0f, 1f });
        Check(Math.Abs(q[1] - Math.Sin(0.5)) < 1e-6 && Math.Abs(q[3] - Math.Cos(0.5)) < 1e-6 && q[0] == 0 && q[2] == 0, "yaw alone");
        // Two yaws compose: 0.25 then 0.75 is 1.
        q = UnityAxes.YawThen(0.75f, UnityAxes.YawThen(0.25f, new[] { 0f, 0f, 0f, 1f }));
        Check(Math.Abs(q[1] - Math.Sin(0.5)) < 1e-6 && Math.Abs(q[3] - Math.Cos(0.5)) < 1e-6, "yaws add");
    }

    static void MalformedHeaders()
    {
        var vector = Vector("bench20");
        var decoder = DecoderOf(vector);
        var got = decoder.NewFrame();
        var key = Hex(Frames(vector)[0]);
        var longer = new byte[key.Length + 1];
        Array.Copy(key, longer, key.Length);
        Refused("compact_trailing_bytes", () => decoder.Decode(longer, got));
        foreach (byte flags in new byte[] { 16, 17, 0x80 })
        {
            var bad = (byte[])key.Clone();
            bad[0] = flags;
            Refused("compact_unknown_flags", () => decoder.Decode(bad, got));
        }
        // seq as eleven bytes with the continuation bit set.
        var overlong = new byte[] { 1, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0x01 };
        Refused("compact_varint_overflow", () => decoder.Decode(overlong, got));
        Refused("compact_truncated", () => decoder.Decode(new byte[0], got));
    }

    static void UnknownEvent()
    {
        var vector = Vector("stepping");
        var decoder = DecoderOf(vector);
        Equal("land", decoder.Layout.EventNames[2], "the layout's events");
        var key = Hex(Frames(vector)[0]); // events [0], then root motion
        Equal((byte)1, key[key.Length - 34], "one event");
        key[key.Length - 33] = 3;
        Refused("compact_unknown_event", () => decoder.Decode(key, decoder.NewFrame()));
    }

    // The vector's three reports, written out from docs/compact-frames/graph-report.json's description: the key
    // frame in idle alone; a delta frame in jump, 1/4 of the way from move, walkrun at 1/4 and 3/4; one in move with
    // walkrun halved and aim at 1/8, 3/8, 1/2 (all exact in f32).
    static void GraphReports()
    {
        var vector = Vector("graph-report");
        var decoder = DecoderOf(vector);
        Equal("idle move jump", string.Join(" ", decoder.Layout.GraphStates), "states");
        Equal("walkrun:2 aim:3", string.Join(" ", decoder.Layout.GraphNodes.Select((n, i) => n + ":" + decoder.Layout.GraphNodePoints[i])), "nodes");
        var got = decoder.NewFrame();
        var frames = Frames(vector);
        decoder.Decode(Hex(frames[0]), got);
        Equal("idle -", Report(decoder.Layout, got.Graph), "the key frame's report");
        decoder.Decode(Hex(frames[1]), got);
        Equal("jump move>jump@0.25 walkrun[0.25,0.75]", Report(decoder.Layout, got.Graph), "the first delta frame's");
        decoder.Decode(Hex(frames[2]), got);
        Equal("move - walkrun[0.5,0.5] aim[0.125,0.375,0.5]", Report(decoder.Layout, got.Graph), "the second delta frame's");
        Check(got.HasRootMotion, "root motion before the report");
        // A frame without the section has no report, however many came before.
        decoder.Decode(Hex(Frames(Vector("half-turn"))[0]), got);
        Check(!got.HasGraph && got.Graph == null, "no report without flags bit 3");
    }

    static string Report(CompactLayout layout, CompactGraphReport r)
    {
        var parts = new List<string> { layout.GraphStates[r.State] };
        var t = r.Transition;
        parts.Add(r.HasTransition ? layout.GraphStates[t.From] + ">" + layout.GraphStates[t.To] + "@" + t.Alpha.ToString(CultureInfo.InvariantCulture) : "-");
        for (int i = 0; i < r.NodeCount; i++)
        {
            var w = r.NodeWeights(i).Select(x => x.ToString(CultureInfo.InvariantCulture));
            parts.Add(layout.GraphNodes[r.Nodes[i]] + "[" + string.Join(",", w) + "]");
        }
        return string.Join(" ", parts);
    }

    // The JavaScript test's cases: the delta frame's state, transition from and to, and node index each set past
    // the layout's three states or two nodes; the frame cut by a byte; the key frame against a layout with no graph.
    static void GraphRefusals()
    {
        var vector = Vector("graph-report");
        var frames = Frames(vector);
        var decoder = DecoderOf(vector);
        var got = decoder.NewFrame();
        decoder.Decode(Hex(frames[0]), got);
        var delta = Hex(frames[1]); // state 2, transition 1 → 2 (from + 1 = 2), alpha, one node: 0, two weights
        int at = delta.Length - 4 - 4 - 1 - 1 - 4 - 1 - 1 - 1;
        Equal((byte)2, delta[at], "the state's byte");
        foreach (var c in new[] { new[] { 0, 3 }, new[] { 1, 4 }, new[] { 2, 3 }, new[] { 8, 2 } })
        {
            var bad = (byte[])delta.Clone();
            bad[at + c[0]] = (byte)c[1];
            Refused("compact_unknown_graph_index", () => decoder.Decode(bad, got));
        }
        Refused("compact_truncated", () => decoder.Decode(delta, 0, delta.Length - 1, got));
        Check(got.Graph.State == 0 && !got.Graph.HasTransition && got.Graph.NodeCount == 0, "a refused report changes nothing");
        decoder.Decode(delta, got);
        Equal(2, got.Graph.State, "the whole frame still decodes after the refusals");
        var plain = (Dictionary<string, object>)vector["layout"];
        plain.Remove("graph");
        Refused("compact_unknown_graph_index", () => new CompactDecoder(CompactLayout.FromJson(plain)).Decode(Hex(frames[0]), got));
        var negative = (Dictionary<string, object>)Vector("graph-report")["layout"];
        var node = (Dictionary<string, object>)((List<object>)((Dictionary<string, object>)negative["graph"])["nodes"])[1];
        node["points"] = -1.0;
        var e = Refused("compact_bad_layout", () => CompactLayout.FromJson(negative));
        Check(e.Message.Contains("/graph/nodes/1/points "), e.Message);
    }

    static void RefusedFrameChangesNothing()
    {
        var vector = Vector("chain");
        var frames = Frames(vector);
        var decoder = DecoderOf(vector);
        var got = decoder.NewFrame();
        decoder.Decode(Hex(frames[0]), got);
        var before = got.Rotations.ToArray();
        // A key frame of another seq, cut short or with a byte too many: neither becomes the key frame.
        var key = Hex(frames[0]);
        key[1] = 0x7e;
        Refused("compact_truncated", () => decoder.Decode(key, 0, key.Length - 1, got));
        var longer = new byte[key.Length + 1];
        Array.Copy(key, longer, key.Length);
        Refused("compact_trailing_bytes", () => decoder.Decode(longer, got));
        SameBits(got.Rotations, before, "the output after refusals");
        Equal((ulong)(double)frames[0]["seq"], got.Seq, "seq after refusals");
        // The delta frames of the first key frame still decode.
        decoder.Decode(Hex(frames[1]), got);
        SameBits(got.Rotations, Flat(frames[1], "rotations"), "rotations of the next delta frame");
    }

    static void RandomBytes()
    {
        var random = new Random(7);
        var vector = Vector("chain");
        var decoder = DecoderOf(vector);
        var got = decoder.NewFrame();
        int decoded = 0;
        for (int i = 0; i < 20000; i++)
        {
            var bytes = new byte[random.Next(0, 40)];
            random.NextBytes(bytes);
            if (bytes.Length > 0) bytes[0] &= 1;
            try
            {
                decoder.Decode(bytes, got);
                decoded++;
            }
            catch (CompactException)
            {
                // Refused with a code: what malformed bytes should get.
            }
        }
        Check(decoded < 20000, "some random frames are refused");
    }

    static void WrongVersion()
    {
        var layout = (Dictionary<string, object>)Vector("chain")["layout"];
        foreach (var version in new object[] { 2.0, 0.0, "1", null })
        {
            layout["version"] = version;
            Refused("compact_version", () => CompactLayout.FromJson(layout));
        }
        layout.Remove("version");
        Refused("compact_bad_layout", () => CompactLayout.FromJson(layout));
        Refused("compact_version", () => new CompactDecoder("{\"version\": 2, \"joints\": []}"));
    }

    static void MalformedLayouts()
    {
        // Each case breaks one member of half-turn's layout and names the JSON pointer the refusal must give.
        var cases = new List<KeyValuePair<string, Action<Dictionary<string, object>>>>
        {
            Case("/joints/0/rotation/smallest_three/bits/2", l => Bits(Smallest(l), 2, 25.0)),
            Case("/joints/0/rotation/smallest_three/bits/0", l => Bits(Smallest(l), 0, -1.0)),
            Case("/joints/0/rotation/smallest_three/bits", l => ((List<object>)Smallest(l)["bits"]).RemoveAt(3)),
            Case("/joints/0/rotation/smallest_three/largest", l => Smallest(l)["largest"] = 4.0),
            Case("/joints/0/rotation/smallest_three/min/1", l => ((List<object>)Smallest(l)["min"])[1] = "0"),
            Case("/joints/0/rotation/smallest_three/max/3", l => ((List<object>)Smallest(l)["max"])[3] = 1e39),
            Case("/joints/0/rotation", l => Joint(l)["rotation"] = new Dictionary<string, object>()),
            Case("/joints/0/translation/min", l => ((Dictionary<string, object>)Joint(l)["translation"])["min"] = 1.0),
            Case("/joints/0/scale", l => Joint(l).Remove("scale")),
            Case("/joints/0/name", l => Joint(l)["name"] = 3.0),
            Case("/joints/0", l => ((List<object>)l["joints"])[0] = null),
            Case("/joints", l => l["joints"] = new Dictionary<string, object>()),
            Case("/key_interval", l => l["key_interval"] = 0.5),
            Case("/bound", l => l["bound"] = null),
        };
        foreach (var c in cases)
        {
            var layout = (Dictionary<string, object>)Vector("half-turn")["layout"];
            c.Value(layout);
            var e = Refused("compact_bad_layout", () => CompactLayout.FromJson(layout));
            Check(e.Message.Contains(c.Key + " "), "'" + e.Message + "' names " + c.Key);
        }
        foreach (var json in new[] { "", "{", "{\"version\": 1,}", "[1 2]", "\"abc", "{\"a\": tru}", "1 2", new string('[', 100) })
        {
            Refused("compact_bad_layout", () => CompactLayout.Parse(json));
        }
    }

    static KeyValuePair<string, Action<Dictionary<string, object>>> Case(string pointer, Action<Dictionary<string, object>> breakIt)
    {
        return new KeyValuePair<string, Action<Dictionary<string, object>>>(pointer, breakIt);
    }

    static Dictionary<string, object> Joint(Dictionary<string, object> layout)
    {
        return (Dictionary<string, object>)((List<object>)layout["joints"])[0];
    }

    static Dictionary<string, object> Smallest(Dictionary<string, object> layout)
    {
        return (Dictionary<string, object>)((Dictionary<string, object>)Joint(layout)["rotation"])["smallest_three"];
    }

    static void Bits(Dictionary<string, object> axes, int k, double value)
    {
        ((List<object>)axes["bits"])[k] = value;
    }

    static void OpenedMessage()
    {
        var text = File.ReadAllText(Path.Combine(vectorsDir, "chain.json"));
        int at = text.IndexOf("\"layout\": ", StringComparison.Ordinal);
        Check(at >= 0, "the vector's layout member");
        var layoutJson = ExtractObject(text, at + "\"layout\": ".Length);
        var opened = "{\"opened\": {\"grid_phase_ms\": 3, \"clip\": \"x\", \"joints\": [], \"compact\": " + layoutJson + "}}";
        var layout = CompactLayout.FromOpened(opened);
        var expected = CompactLayout.FromJson(Vector("chain")["layout"]);
        Equal(string.Join(",", expected.Names), string.Join(",", layout.Names), "names");
        Equal(expected.KeyInterval, layout.KeyInterval, "key_interval");
        Equal(expected.Bound, layout.Bound, "bound");
        Refused("compact_bad_layout", () => CompactLayout.FromOpened("{\"opened\": {\"clip\": \"x\"}}"));
    }

    // The conversions against the change of basis each stands for: with S the mirror of X (GltfToUnity) or of Z
    // (GltfToUnityMirrorZ), the converted local transform (T', R') must be (S·T, S·R·S), R from the quaternion by the
    // usual formula (the one Unity's Quaternion uses).
    static void AxisConversionIsTheMirror()
    {
        var random = new Random(11);
        var mirrors = new[]
        {
            new KeyValuePair<AxisConversion, double[]>(AxisConversion.GltfToUnity, new double[] { -1, 1, 1 }),
            new KeyValuePair<AxisConversion, double[]>(AxisConversion.GltfToUnityMirrorZ, new double[] { 1, 1, -1 }),
            new KeyValuePair<AxisConversion, double[]>(AxisConversion.None, new double[] { 1, 1, 1 }),
        };
        for (int i = 0; i < 1000; i++)
        {
            var q = new double[4];
            double norm = 0;
            for (int k = 0; k < 4; k++)
            {
                q[k] = random.NextDouble() * 2 - 1;
                norm += q[k] * q[k];
            }
            var r = q.Select(c => (float)(c / Math.Sqrt(norm))).ToArray();
            var t = new[] { (float)random.NextDouble(), (float)random.NextDouble() - 0.5f, 2f * (float)random.NextDouble() };
            foreach (var mirror in mirrors)
            {
                var rc = (float[])r.Clone();
                var tc = (float[])t.Clone();
                UnityAxes.Convert(mirror.Key, tc, rc, 1);
                var s = mirror.Value;
                var m = Matrix(r);
                var mc = Matrix(rc);
                for (int a = 0; a < 3; a++)
                {
                    Near(new[] { tc[a] }, new[] { (float)(s[a] * t[a]) }, 0, mirror.Key + " translation " + a);
                    for (int b = 0; b < 3; b++)
                    {
                        double mirrored = s[a] * m[a, b] * s[b];
                        Check(Math.Abs(mc[a, b] - mirrored) < 1e-6, mirror.Key + " rotation matrix [" + a + "," + b + "]: " + mc[a, b] + " vs " + mirrored);
                    }
                }
            }
        }
    }

    static double[,] Matrix(float[] q)
    {
        double x = q[0], y = q[1], z = q[2], w = q[3];
        return new[,]
        {
            { 1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w) },
            { 2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w) },
            { 2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y) },
        };
    }

    // ---- helpers ----

    static int VarintLength(byte[] bytes, int at)
    {
        int n = 1;
        while ((bytes[at + n - 1] & 0x80) != 0) n++;
        return n;
    }

    // The JSON object starting at `at` (balanced braces; the layout holds no strings with braces).
    static string ExtractObject(string text, int at)
    {
        int depth = 0;
        for (int i = at; i < text.Length; i++)
        {
            if (text[i] == '{') depth++;
            if (text[i] == '}' && --depth == 0) return text.Substring(at, i - at + 1);
        }
        throw new Exception("unbalanced braces");
    }

    static CompactException Refused(string code, Action decode)
    {
        try
        {
            decode();
        }
        catch (CompactException e)
        {
            Check(e.Code == code, "refused " + e.Code + " (" + e.Message + "), expected " + code);
            return e;
        }
        throw new Exception("accepted, expected " + code);
    }

    static void Check(bool ok, string what)
    {
        if (!ok) throw new Exception(what);
    }

    static void Equal<T>(T expected, T got, string what)
    {
        if (!EqualityComparer<T>.Default.Equals(expected, got)) throw new Exception(what + ": " + got + ", expected " + expected);
    }

    static void SameBits(float[] got, float[] expected, string what)
    {
        Check(got.Length >= expected.Length, what + ": " + got.Length + " values, expected " + expected.Length);
        for (int i = 0; i < expected.Length; i++)
        {
            if (BitConverter.DoubleToInt64Bits(got[i]) != BitConverter.DoubleToInt64Bits(expected[i]))
            {
                throw new Exception(what + "[" + i + "]: " + got[i].ToString("R") + ", expected " + expected[i].ToString("R"));
            }
        }
    }

    static void Near(float[] got, float[] expected, double tolerance, string what)
    {
        for (int i = 0; i < expected.Length; i++)
        {
            if (Math.Abs(got[i] - expected[i]) > tolerance)
            {
                throw new Exception(what + "[" + i + "]: " + got[i].ToString("R") + ", expected " + expected[i].ToString("R") + " within " + tolerance);
            }
        }
    }
}
