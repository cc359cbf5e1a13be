// Compact frames (docs/compact-frames.md): a decoder for the binary frames of
// `encoding=compact` streams, for C# game engines (Unity, Godot .NET). No
// dependencies beyond mscorlib; C# 7, so Mono's `mcs` and Unity compile it.
//
//   var decoder = new CompactDecoder(CompactLayout.FromOpened(openedText)); // the stream's first message
//   var frame = decoder.NewFrame();                  // arrays sized for the layout, allocated once
//   decoder.Decode(message, 0, length, frame);       // frame.Rotations, frame.Seq, ...
//
// A decoder keeps the last key frame's values, so feed it every frame of one
// stream in order. Decoding writes into the caller's arrays and allocates
// nothing. Bytes that are not a frame of the layout throw CompactException
// with a stable Code (the same codes as the Rust and JavaScript decoders), and
// leave the decoder and the output as they were.

using System;
using System.Collections.Generic;
using System.Globalization;
using System.Text;

namespace Inbetween
{
    /// <summary>Bytes that are not a compact frame of a layout, or a layout this decoder cannot read.</summary>
    public sealed class CompactException : Exception
    {
        /// <summary>Stable: compact_truncated, compact_unknown_flags, compact_trailing_bytes,
        /// compact_missing_key_frame, compact_varint_overflow, compact_unknown_event,
        /// compact_unknown_graph_index, compact_version, compact_bad_layout.</summary>
        public readonly string Code;

        public CompactException(string code, string message) : base(code + ": " + message)
        {
            Code = code;
        }
    }

    /// <summary>One decoded frame: its header and the pose, in caller-owned arrays reused by every decode.</summary>
    public sealed class CompactFrame
    {
        public bool Key;
        public ulong Seq;
        public ulong Dropped;
        /// <summary>The seq of the key frame this frame's values are relative to (its own for a key frame).</summary>
        public ulong KeySeq;
        public long SentAtUnixNanos;
        public float ClipTime;
        /// <summary>How many joints' fields the frame carried (all of them in a key frame).</summary>
        public int JointsSent;
        /// <summary>Local translations, 3 floats per joint in the layout's joint order.</summary>
        public float[] Translations;
        /// <summary>Local rotations, 4 floats per joint, [x, y, z, w].</summary>
        public float[] Rotations;
        /// <summary>Local scales, 3 floats per joint.</summary>
        public float[] Scales;
        /// <summary>The events crossed since the previous frame, in order: the first EventCount entries are
        /// indices into the layout's EventNames and EventTimes. Grown by a decode that needs more room.</summary>
        public int[] Events = new int[8];
        public int EventCount;
        /// <summary>Whether the frame reports root motion (then RootMotion holds it).</summary>
        public bool HasRootMotion;
        /// <summary>The root motion report: delta x, y, z, yaw, then total x, y, z, yaw (docs/motion.md).</summary>
        public readonly float[] RootMotion = new float[8];
        /// <summary>Whether the frame carries a graph stream's report (then Graph holds it).</summary>
        public bool HasGraph;
        // Kept across decodes so that reading a report allocates nothing once it has grown.
        private readonly CompactGraphReport graph = new CompactGraphReport();

        /// <summary>A graph stream's report of the tick (docs/compact-frames.md, "The graph report section"), by
        /// index into the layout's GraphStates and GraphNodes; null when the frame carries none.</summary>
        public CompactGraphReport Graph
        {
            get { return HasGraph ? graph : null; }
        }

        /// <summary>The report a decode fills; the same object every time.</summary>
        internal CompactGraphReport GraphStore
        {
            get { return graph; }
        }

        public CompactFrame(float[] translations, float[] rotations, float[] scales)
        {
            Translations = translations;
            Rotations = rotations;
            Scales = scales;
        }
    }

    /// <summary>A graph's transition in progress: from and to as indices into the layout's GraphStates.</summary>
    public struct CompactTransition
    {
        public int From;
        public int To;
        /// <summary>How far the crossfade has gone, 0 to 1 (the JSON frame's alpha rounded to f32).</summary>
        public float Alpha;
    }

    /// <summary>
    /// A graph stream's report of one tick (docs/graphs.md, "Reports"): the current state, the transition in
    /// progress and the weights of each blend node the tick evaluated, all by index into the layout's graph.
    /// </summary>
    public sealed class CompactGraphReport
    {
        /// <summary>The current state's index in the layout's GraphStates.</summary>
        public int State;
        /// <summary>Whether a transition is in progress (then Transition holds it).</summary>
        public bool HasTransition;
        public CompactTransition Transition;
        /// <summary>How many blend nodes the tick evaluated: the first NodeCount entries of Nodes.</summary>
        public int NodeCount;
        /// <summary>Each evaluated node's index in the layout's GraphNodes, in the frame's order.</summary>
        public int[] Nodes = new int[4];
        // The evaluated nodes' weights one after another; entry i's start at starts[i].
        internal float[] weights = new float[16];
        internal int[] starts = new int[4];
        internal int WeightCount;

        /// <summary>The weights of the i-th evaluated node (as many as its GraphNodePoints), in its points' order.</summary>
        public ArraySegment<float> NodeWeights(int i)
        {
            if (i < 0 || i >= NodeCount) throw new ArgumentOutOfRangeException("i", i + " is not below the " + NodeCount + " nodes reported");
            int end = i + 1 < NodeCount ? starts[i + 1] : WeightCount;
            return new ArraySegment<float>(weights, starts[i], end - starts[i]);
        }

        /// <summary>Copies <paramref name="other"/> into this report, growing its arrays when they are too short.</summary>
        internal void CopyFrom(CompactGraphReport other)
        {
            State = other.State;
            HasTransition = other.HasTransition;
            Transition = other.Transition;
            NodeCount = other.NodeCount;
            WeightCount = other.WeightCount;
            if (Nodes.Length < NodeCount) Nodes = new int[other.Nodes.Length];
            if (starts.Length < NodeCount) starts = new int[other.starts.Length];
            if (weights.Length < WeightCount) weights = new float[other.weights.Length];
            Array.Copy(other.Nodes, Nodes, NodeCount);
            Array.Copy(other.starts, starts, NodeCount);
            Array.Copy(other.weights, weights, WeightCount);
        }
    }

    /// <summary>One quantised channel: value = min + (u * (max - min)) / (2^bits - 1), in doubles.</summary>
    internal struct CompactField
    {
        public int Bits;
        public double Min;
        public double Span;
        public double Levels;

        public CompactField(int bits, float min, float max)
        {
            Bits = bits;
            Min = min;
            Span = (double)max - min;
            Levels = (1L << bits) - 1;
        }

        public double Value(int u)
        {
            return Bits == 0 ? Min : Min + (u * Span) / Levels;
        }
    }

    /// <summary>A joint's widths and ranges.</summary>
    internal sealed class CompactJoint
    {
        /// <summary>The rotation of every frame, [x, y, z, w]; null when it is sent (smallest three).</summary>
        public float[] Constant;
        /// <summary>The index of the rebuilt component, or -1 when each frame sends it.</summary>
        public int Largest;
        public CompactField[] Components;
        public CompactField[] Translation;
        public CompactField[] Scale;
        /// <summary>Has at least one non-constant channel: a delta frame spends a bit on it.</summary>
        public bool Animated;
    }

    /// <summary>
    /// The layout document of a compact stream (docs/compact-frames.md, "The layout document"), parsed and checked
    /// once so that decoding cannot meet a malformed layout.
    /// </summary>
    public sealed class CompactLayout
    {
        /// <summary>The widths this decoder reads at most (anim::compact's MAX_BITS).</summary>
        public const int MaxBits = 24;

        public int Version;
        public float MaxError;
        public float Distance;
        public float Bound;
        public int KeyInterval;
        /// <summary>The joints' names in skeleton order (parents first), the order of the pose arrays.</summary>
        public string[] Names;
        /// <summary>The events a frame's Events index: their names and clip times (empty when there are none).</summary>
        public string[] EventNames = new string[0];
        public float[] EventTimes = new float[0];
        /// <summary>A graph stream's states and blend nodes (names, and how many weights each node has), which a
        /// frame's Graph indexes; empty unless the stream asked for <c>report</c>.</summary>
        public string[] GraphStates = new string[0];
        public string[] GraphNodes = new string[0];
        public int[] GraphNodePoints = new int[0];
        internal CompactJoint[] Joints;

        /// <summary>Parses a layout document (the `compact` member of an `opened` message).</summary>
        public static CompactLayout Parse(string json)
        {
            return FromJson(CompactJson.Parse(json));
        }

        /// <summary>Parses a stream's `opened` message, <c>{"opened":{…,"compact":layout}}</c>, for its layout.</summary>
        public static CompactLayout FromOpened(string openedMessage)
        {
            var opened = Reader.Member(CompactJson.Parse(openedMessage), "opened", "");
            return FromJson(Reader.Member(opened, "compact", "/opened"));
        }

        /// <summary>A layout from a parsed JSON value (CompactJson's objects, arrays and doubles).</summary>
        public static CompactLayout FromJson(object document)
        {
            var version = Reader.Member(document, "version", "");
            if (!(version is double) || (double)version != 1)
            {
                throw new CompactException("compact_version", "layout version " + CompactJson.Show(version) + ", this decoder reads 1");
            }
            var layout = new CompactLayout { Version = 1 };
            layout.MaxError = Reader.Float(document, "max_error", "");
            layout.Distance = Reader.Float(document, "distance", "");
            layout.Bound = Reader.Float(document, "bound", "");
            layout.KeyInterval = Reader.Int(document, "key_interval", "", 1, int.MaxValue);
            var joints = Reader.List(Reader.Member(document, "joints", ""), "/joints");
            layout.Names = new string[joints.Count];
            layout.Joints = new CompactJoint[joints.Count];
            for (int j = 0; j < joints.Count; j++)
            {
                var path = "/joints/" + j;
                layout.Names[j] = Reader.String(joints[j], "name", path);
                layout.Joints[j] = ReadJoint(joints[j], path);
            }
            if (Reader.Has(document, "events")) ReadEvents(layout, Reader.List(Reader.Member(document, "events", ""), "/events"));
            if (Reader.Has(document, "graph")) ReadGraph(layout, Reader.Member(document, "graph", ""));
            return layout;
        }

        // The layout's `graph`: {"states": [names], "nodes": [{"name", "points"}]}.
        private static void ReadGraph(CompactLayout layout, object graph)
        {
            var states = Reader.List(Reader.Member(graph, "states", "/graph"), "/graph/states");
            layout.GraphStates = new string[states.Count];
            for (int i = 0; i < states.Count; i++)
            {
                layout.GraphStates[i] = states[i] as string;
                if (layout.GraphStates[i] == null) throw Reader.Bad("/graph/states/" + i, "is not a string");
            }
            var nodes = Reader.List(Reader.Member(graph, "nodes", "/graph"), "/graph/nodes");
            layout.GraphNodes = new string[nodes.Count];
            layout.GraphNodePoints = new int[nodes.Count];
            for (int i = 0; i < nodes.Count; i++)
            {
                layout.GraphNodes[i] = Reader.String(nodes[i], "name", "/graph/nodes/" + i);
                // A node's weights are f32s of one frame: far fewer than 2^24.
                layout.GraphNodePoints[i] = Reader.Int(nodes[i], "points", "/graph/nodes/" + i, 0, 1 << 24);
            }
        }

        private static void ReadEvents(CompactLayout layout, List<object> events)
        {
            layout.EventNames = new string[events.Count];
            layout.EventTimes = new float[events.Count];
            for (int i = 0; i < events.Count; i++)
            {
                layout.EventNames[i] = Reader.String(events[i], "name", "/events/" + i);
                layout.EventTimes[i] = Reader.Float(events[i], "time", "/events/" + i);
            }
        }

        private static CompactJoint ReadJoint(object joint, string path)
        {
            var compiled = new CompactJoint
            {
                Largest = -1,
                Translation = ReadFields(Reader.Member(joint, "translation", path), path + "/translation", 3),
                Scale = ReadFields(Reader.Member(joint, "scale", path), path + "/scale", 3),
            };
            var rotation = Reader.Member(joint, "rotation", path);
            var rotationPath = path + "/rotation";
            if (Reader.Has(rotation, "constant"))
            {
                compiled.Constant = Reader.Floats(Reader.Member(rotation, "constant", rotationPath), rotationPath + "/constant", 4);
            }
            else
            {
                if (!Reader.Has(rotation, "smallest_three")) throw Reader.Bad(rotationPath, "is neither constant nor smallest_three");
                var smallest = Reader.Member(rotation, "smallest_three", rotationPath);
                var smallestPath = rotationPath + "/smallest_three";
                compiled.Components = ReadFields(smallest, smallestPath, 4);
                var largest = Reader.Member(smallest, "largest", smallestPath);
                if (largest != null)
                {
                    compiled.Largest = Reader.Int(smallest, "largest", smallestPath, 0, 3);
                }
            }
            compiled.Animated = compiled.Constant == null;
            foreach (var f in compiled.Translation) compiled.Animated |= f.Bits > 0;
            foreach (var f in compiled.Scale) compiled.Animated |= f.Bits > 0;
            return compiled;
        }

        private static CompactField[] ReadFields(object axes, string path, int count)
        {
            var bits = Reader.List(Reader.Member(axes, "bits", path), path + "/bits");
            var min = Reader.Floats(Reader.Member(axes, "min", path), path + "/min", count);
            var max = Reader.Floats(Reader.Member(axes, "max", path), path + "/max", count);
            if (bits.Count != count) throw Reader.Bad(path + "/bits", "has " + bits.Count + " entries, not " + count);
            var fields = new CompactField[count];
            for (int k = 0; k < count; k++)
            {
                var b = bits[k] as double?;
                if (b == null || b < 0 || b > MaxBits || b != Math.Floor(b.Value))
                {
                    throw Reader.Bad(path + "/bits/" + k, "is not a width from 0 to " + MaxBits);
                }
                fields[k] = new CompactField((int)b.Value, min[k], max[k]);
            }
            return fields;
        }

        /// <summary>Typed access to parsed JSON, refusing with the JSON pointer of what is wrong.</summary>
        private static class Reader
        {
            public static CompactException Bad(string pointer, string what)
            {
                return new CompactException("compact_bad_layout", (pointer.Length == 0 ? "the layout" : pointer) + " " + what);
            }

            public static bool Has(object value, string name)
            {
                var o = value as Dictionary<string, object>;
                return o != null && o.ContainsKey(name);
            }

            public static object Member(object value, string name, string path)
            {
                var o = value as Dictionary<string, object>;
                if (o == null) throw Bad(path, "is not an object");
                object member;
                if (!o.TryGetValue(name, out member)) throw Bad(path + "/" + name, "is missing");
                return member;
            }

            public static List<object> List(object value, string path)
            {
                var list = value as List<object>;
                if (list == null) throw Bad(path, "is not an array");
                return list;
            }

            public static string String(object value, string name, string path)
            {
                var s = Member(value, name, path) as string;
                if (s == null) throw Bad(path + "/" + name, "is not a string");
                return s;
            }

            public static float Float(object value, string name, string path)
            {
                return ToFloat(Member(value, name, path), path + "/" + name);
            }

            public static int Int(object value, string name, string path, int lo, int hi)
            {
                var d = Member(value, name, path) as double?;
                if (d == null || d < lo || d > hi || d != Math.Floor(d.Value))
                {
                    throw Bad(path + "/" + name, "is not a whole number from " + lo + " to " + hi);
                }
                return (int)d.Value;
            }

            public static float[] Floats(object value, string path, int count)
            {
                var list = List(value, path);
                if (list.Count != count) throw Bad(path, "has " + list.Count + " entries, not " + count);
                var floats = new float[count];
                for (int k = 0; k < count; k++) floats[k] = ToFloat(list[k], path + "/" + k);
                return floats;
            }

            // The layout's numbers are exactly f32 values written as JSON numbers: read as f64, rounded to f32.
            private static float ToFloat(object value, string path)
            {
                var d = value as double?;
                if (d == null) throw Bad(path, "is not a number");
                var f = (float)d.Value;
                if (float.IsInfinity(f) || float.IsNaN(f)) throw Bad(path, "is not a finite f32");
                return f;
            }
        }
    }

    /// <summary>Decodes one stream's compact frames against its layout.</summary>
    public sealed class CompactDecoder
    {
        private const int KeyFrameFlag = 1;
        private const int EventsFlag = 2;
        private const int RootMotionFlag = 4;
        private const int GraphFlag = 8;
        private const int KnownFlags = KeyFrameFlag | EventsFlag | RootMotionFlag | GraphFlag;
        // Per joint in a value store: largest index, three rotation components, translation x y z, scale x y z.
        private const int Stride = 10;

        public CompactLayout Layout { get; private set; }
        private CompactJoint[] joints;
        // The quantised values of the last key frame, and scratch for the frame being read: a frame that turns out
        // malformed half-way leaves `key` and the caller's arrays untouched.
        private int[] key;
        private int[] values;
        private bool hasKey;
        private ulong keySeq;
        private readonly double[] small = new double[3];
        // The frame being read's events, root motion and graph report, copied out once it is whole.
        private int[] events = new int[8];
        private readonly float[] rootMotion = new float[8];
        private readonly CompactGraphReport graph = new CompactGraphReport();

        public CompactDecoder(CompactLayout layout)
        {
            Relayout(layout);
        }

        /// <summary>
        /// Decodes frames of <paramref name="layout"/> from now on (docs/compact-frames.md, "A new layout": a
        /// WebSocket text message {"layout", "seq"}, or a later Frame's compact_layout on gRPC). The last key frame
        /// is forgotten, so a delta frame before the new layout's first key frame is refused. The skeleton is the
        /// stream's, so frames from <see cref="NewFrame"/> keep fitting.
        /// </summary>
        public void Relayout(CompactLayout layout)
        {
            if (layout == null) throw new ArgumentNullException("layout");
            Layout = layout;
            joints = layout.Joints;
            key = new int[joints.Length * Stride];
            values = new int[joints.Length * Stride];
            hasKey = false;
        }

        /// <summary>Parses the layout document (JSON) and decodes against it from now on.</summary>
        public void Relayout(string layoutJson)
        {
            Relayout(CompactLayout.Parse(layoutJson));
        }

        /// <summary>Parses the layout document (JSON) and decodes against it.</summary>
        public CompactDecoder(string layoutJson) : this(CompactLayout.Parse(layoutJson))
        {
        }

        /// <summary>The joints' names, in the order of the pose arrays.</summary>
        public string[] Names
        {
            get { return Layout.Names; }
        }

        public int JointCount
        {
            get { return joints.Length; }
        }

        /// <summary>A frame with arrays sized for this layout, to decode into again and again.</summary>
        public CompactFrame NewFrame()
        {
            int n = joints.Length;
            return new CompactFrame(new float[n * 3], new float[n * 4], new float[n * 3]);
        }

        /// <summary>Decodes the whole of <paramref name="bytes"/> into <paramref name="frame"/>.</summary>
        public CompactFrame Decode(byte[] bytes, CompactFrame frame)
        {
            if (bytes == null) throw new ArgumentNullException("bytes");
            return Decode(bytes, 0, bytes.Length, frame);
        }

        /// <summary>
        /// Decodes the frame in <paramref name="bytes"/>[offset .. offset + count) into <paramref name="frame"/>'s
        /// header fields and arrays (at least 3, 4 and 3 floats per joint), and returns it.
        /// Throws CompactException when the bytes are not a frame of the layout (nothing is changed then).
        /// </summary>
        public CompactFrame Decode(byte[] bytes, int offset, int count, CompactFrame frame)
        {
            CheckArguments(bytes, offset, count, frame);
            int end = offset + count;
            if (count == 0) throw Truncated("flags");
            int flags = bytes[offset];
            if ((flags & ~KnownFlags) != 0)
            {
                throw new CompactException("compact_unknown_flags", "flags 0x" + flags.ToString("x2") + " use bits other than key frame, events, root motion and graph");
            }
            bool isKey = (flags & KeyFrameFlag) != 0;
            int at = offset + 1;
            ulong seq = ReadVarint(bytes, ref at, end, "seq");
            ulong dropped = ReadVarint(bytes, ref at, end, "dropped");
            ulong frameKeySeq = unchecked(seq - ReadVarint(bytes, ref at, end, "key offset"));
            ulong zigzag = ReadVarint(bytes, ref at, end, "sent_at");
            long sentAt = (long)(zigzag >> 1) ^ -(long)(zigzag & 1);
            if (end - at < 4) throw Truncated("clip time");
            float clipTime = ReadFloat(bytes, at);
            var bits = new BitReader(bytes, at + 4, end);
            int sent;
            if (isKey)
            {
                sent = ReadKey(ref bits);
            }
            else
            {
                if (!hasKey || keySeq != frameKeySeq)
                {
                    throw new CompactException(
                        "compact_missing_key_frame",
                        "a delta frame refers to key frame " + frameKeySeq + ", and the last key frame seen is " + (hasKey ? keySeq.ToString() : "none"));
                }
                sent = ReadDelta(ref bits);
            }
            at = bits.BytesEnd;
            int eventCount = (flags & EventsFlag) != 0 ? ReadEvents(bytes, ref at, end) : 0;
            bool hasRoot = (flags & RootMotionFlag) != 0;
            if (hasRoot)
            {
                if (end - at < 32) throw Truncated("root motion");
                for (int k = 0; k < 8; k++) rootMotion[k] = ReadFloat(bytes, at + 4 * k);
                at += 32;
            }
            bool hasGraph = (flags & GraphFlag) != 0;
            if (hasGraph) ReadGraph(bytes, ref at, end);
            int trailing = end - at;
            if (trailing != 0)
            {
                throw new CompactException("compact_trailing_bytes", trailing + " bytes follow the frame's last field");
            }
            if (isKey)
            {
                Array.Copy(values, key, values.Length);
                keySeq = seq;
                hasKey = true;
            }
            Dequantise(frame);
            frame.Key = isKey;
            frame.Seq = seq;
            frame.Dropped = dropped;
            frame.KeySeq = frameKeySeq;
            frame.SentAtUnixNanos = sentAt;
            frame.ClipTime = clipTime;
            frame.JointsSent = sent;
            if (frame.Events == null || frame.Events.Length < eventCount) frame.Events = new int[events.Length];
            Array.Copy(events, frame.Events, eventCount);
            frame.EventCount = eventCount;
            frame.HasRootMotion = hasRoot;
            if (hasRoot) Array.Copy(rootMotion, frame.RootMotion, 8);
            frame.HasGraph = hasGraph;
            if (hasGraph) frame.GraphStore.CopyFrom(graph);
            return frame;
        }

        // The graph report section: the state, the transition (0, or from + 1, to and alpha), then each evaluated
        // blend node's index and weights; indices past the layout's graph are refused as the other decoders do.
        private void ReadGraph(byte[] bytes, ref int at, int end)
        {
            int states = Layout.GraphStates.Length;
            graph.State = GraphIndex(ReadVarint(bytes, ref at, end, "graph report"), states, "state");
            ulong from = ReadVarint(bytes, ref at, end, "graph report");
            graph.HasTransition = from != 0;
            graph.Transition = default(CompactTransition);
            if (from != 0)
            {
                graph.Transition.From = GraphIndex(from - 1, states, "state");
                graph.Transition.To = GraphIndex(ReadVarint(bytes, ref at, end, "graph report"), states, "state");
                if (end - at < 4) throw Truncated("graph report");
                graph.Transition.Alpha = ReadFloat(bytes, at);
                at += 4;
            }
            ulong count = ReadVarint(bytes, ref at, end, "graph report");
            graph.WeightCount = 0;
            graph.NodeCount = 0;
            for (ulong n = 0; n < count; n++)
            {
                int node = GraphIndex(ReadVarint(bytes, ref at, end, "graph report"), Layout.GraphNodes.Length, "node");
                int i = graph.NodeCount;
                if (i == graph.Nodes.Length)
                {
                    Array.Resize(ref graph.Nodes, 2 * i);
                    Array.Resize(ref graph.starts, 2 * i);
                }
                graph.Nodes[i] = node;
                graph.starts[i] = graph.WeightCount;
                graph.NodeCount = i + 1;
                ReadWeights(bytes, ref at, end, Layout.GraphNodePoints[node]);
            }
        }

        // A node's `points` little-endian f32 weights, after the weights read so far.
        private void ReadWeights(byte[] bytes, ref int at, int end, int points)
        {
            if ((end - at) / 4 < points) throw Truncated("graph report");
            int start = graph.WeightCount;
            if (graph.weights.Length < start + points) Array.Resize(ref graph.weights, Math.Max(2 * graph.weights.Length, start + points));
            for (int k = 0; k < points; k++) graph.weights[start + k] = ReadFloat(bytes, at + 4 * k);
            at += 4 * points;
            graph.WeightCount = start + points;
        }

        private static int GraphIndex(ulong index, int known, string what)
        {
            if (index >= (ulong)known)
            {
                throw new CompactException("compact_unknown_graph_index", "graph " + what + " " + index + " is not in the layout's " + known);
            }
            return (int)index;
        }

        // The events section: a count, then indices into the layout's events.
        private int ReadEvents(byte[] bytes, ref int at, int end)
        {
            ulong count = ReadVarint(bytes, ref at, end, "events");
            int known = Layout.EventNames.Length;
            for (ulong n = 0; n < count; n++)
            {
                ulong index = ReadVarint(bytes, ref at, end, "events");
                if (index >= (ulong)known)
                {
                    throw new CompactException("compact_unknown_event", "event " + index + " is not in the layout's " + known + " events");
                }
                if ((int)n == events.Length) Array.Resize(ref events, 2 * events.Length);
                events[n] = (int)index;
            }
            return (int)count;
        }

        private void CheckArguments(byte[] bytes, int offset, int count, CompactFrame frame)
        {
            if (bytes == null) throw new ArgumentNullException("bytes");
            if (frame == null) throw new ArgumentNullException("frame");
            if (offset < 0 || count < 0 || count > bytes.Length - offset)
            {
                throw new ArgumentOutOfRangeException("count", "offset " + offset + " and count " + count + " are not within " + bytes.Length + " bytes");
            }
            int n = joints.Length;
            if (frame.Translations == null || frame.Translations.Length < 3 * n
                || frame.Rotations == null || frame.Rotations.Length < 4 * n
                || frame.Scales == null || frame.Scales.Length < 3 * n)
            {
                throw new ArgumentException("the frame's arrays hold fewer than 3, 4 and 3 floats for each of " + n + " joints (CompactDecoder.NewFrame sizes them)", "frame");
            }
        }

        private int ReadKey(ref BitReader bits)
        {
            for (int j = 0; j < joints.Length; j++) ReadJoint(ref bits, j);
            return joints.Length;
        }

        private int ReadDelta(ref BitReader bits)
        {
            Array.Copy(key, values, key.Length);
            int sent = 0;
            for (int j = 0; j < joints.Length; j++)
            {
                if (joints[j].Animated && bits.Read(1) == 1)
                {
                    ReadJoint(ref bits, j);
                    sent++;
                }
            }
            return sent;
        }

        private void ReadJoint(ref BitReader bits, int j)
        {
            var joint = joints[j];
            int o = j * Stride;
            if (joint.Constant == null)
            {
                int largest = joint.Largest >= 0 ? joint.Largest : bits.Read(2);
                values[o] = largest;
                for (int k = 0, slot = 1; k < 4; k++)
                {
                    if (k != largest) values[o + slot++] = bits.Read(joint.Components[k].Bits);
                }
            }
            for (int a = 0; a < 3; a++) values[o + 4 + a] = bits.Read(joint.Translation[a].Bits);
            for (int a = 0; a < 3; a++) values[o + 7 + a] = bits.Read(joint.Scale[a].Bits);
        }

        // docs/compact-frames.md, "Decoding values": doubles throughout, each result rounded to f32 once.
        private void Dequantise(CompactFrame frame)
        {
            for (int j = 0; j < joints.Length; j++)
            {
                var joint = joints[j];
                int o = j * Stride;
                if (joint.Constant != null)
                {
                    Array.Copy(joint.Constant, 0, frame.Rotations, j * 4, 4);
                }
                else
                {
                    Rebuild(joint, o, frame.Rotations, j * 4);
                }
                for (int a = 0; a < 3; a++)
                {
                    frame.Translations[j * 3 + a] = (float)joint.Translation[a].Value(values[o + 4 + a]);
                    frame.Scales[j * 3 + a] = (float)joint.Scale[a].Value(values[o + 7 + a]);
                }
            }
        }

        // A smallest-three rotation: the three sent components, and the largest rebuilt (never negative).
        private void Rebuild(CompactJoint joint, int o, float[] rotations, int r)
        {
            int largest = values[o];
            for (int k = 0, slot = 0; k < 4; k++)
            {
                if (k != largest)
                {
                    small[slot] = joint.Components[k].Value(values[o + 1 + slot]);
                    slot++;
                }
            }
            double sum = small[0] * small[0] + small[1] * small[1] + small[2] * small[2];
            double big = 0;
            if (sum < 1)
            {
                big = Math.Sqrt(1 - sum);
            }
            else
            {
                double norm = Math.Sqrt(sum);
                for (int s = 0; s < 3; s++) small[s] = small[s] / norm;
            }
            for (int k = 0, slot = 0; k < 4; k++) rotations[r + k] = (float)(k == largest ? big : small[slot++]);
        }

        private static CompactException Truncated(string what)
        {
            return new CompactException("compact_truncated", "the frame ends before its " + what);
        }

        // LEB128, at most 10 bytes (64 bits), as the Rust decoder reads it.
        private static ulong ReadVarint(byte[] bytes, ref int at, int end, string what)
        {
            ulong value = 0;
            for (int shift = 0; shift < 64; shift += 7)
            {
                if (at >= end) throw Truncated(what);
                int b = bytes[at++];
                value |= (ulong)(b & 0x7f) << shift;
                if ((b & 0x80) == 0) return value;
            }
            throw new CompactException("compact_varint_overflow", "a varint is longer than 64 bits");
        }

        // A little-endian f32, whatever the host's byte order.
        private static float ReadFloat(byte[] bytes, int at)
        {
            if (BitConverter.IsLittleEndian) return BitConverter.ToSingle(bytes, at);
            var swapped = new[] { bytes[at + 3], bytes[at + 2], bytes[at + 1], bytes[at] };
            return BitConverter.ToSingle(swapped, 0);
        }

        /// <summary>Bit fields packed least significant bit first (docs/compact-frames.md, "Bit order").</summary>
        private struct BitReader
        {
            private readonly byte[] bytes;
            // Bit positions from bytes[0]; a frame is far below 2^28 bytes, so they fit an int.
            private readonly int endBit;
            private int bit;

            public BitReader(byte[] bytes, int start, int end)
            {
                if (end > int.MaxValue / 8) throw new ArgumentOutOfRangeException("end", "a frame this far into a buffer");
                this.bytes = bytes;
                endBit = end * 8;
                bit = start * 8;
            }

            /// <summary>The index just past the last byte the fields read so far touch.</summary>
            public int BytesEnd
            {
                get { return (bit + 7) >> 3; }
            }

            // Widths are at most 24 bits and the offset in the first byte at most 7: four bytes hold a field.
            public int Read(int width)
            {
                if (width == 0) return 0;
                if (bit + width > endBit) throw Truncated("joint values");
                int first = bit >> 3;
                uint word;
                if (bit + 32 - (bit & 7) <= endBit)
                {
                    word = bytes[first] | ((uint)bytes[first + 1] << 8) | ((uint)bytes[first + 2] << 16) | ((uint)bytes[first + 3] << 24);
                }
                else
                {
                    // Near the end: only the bytes the field touches.
                    word = 0;
                    int last = (bit + width - 1) >> 3;
                    for (int i = first; i <= last; i++) word |= (uint)bytes[i] << (8 * (i - first));
                }
                int value = (int)((word >> (bit & 7)) & ((1u << width) - 1));
                bit += width;
                return value;
            }
        }
    }

    /// <summary>
    /// A small JSON reader for the layout and the stream's text messages: objects become
    /// Dictionary&lt;string, object&gt;, arrays List&lt;object&gt;, numbers double, and true, false and null
    /// bool and null. Malformed text throws CompactException "compact_bad_layout" with the character offset.
    /// </summary>
    public static class CompactJson
    {
        public static object Parse(string text)
        {
            if (text == null) throw new ArgumentNullException("text");
            int at = 0;
            var value = ReadValue(text, ref at, 0);
            SkipSpace(text, ref at);
            if (at != text.Length) throw Bad(at, "text follows the value");
            return value;
        }

        /// <summary>A value for a message: a string quoted, anything else by its JSON-ish form.</summary>
        public static string Show(object value)
        {
            if (value == null) return "null";
            if (value is string) return "\"" + value + "\"";
            if (value is double) return ((double)value).ToString("R", CultureInfo.InvariantCulture);
            if (value is bool) return (bool)value ? "true" : "false";
            return value is List<object> ? "an array" : "an object";
        }

        // Nesting deeper than this is refused rather than allowed to exhaust the stack.
        private const int MaxDepth = 64;

        private static CompactException Bad(int at, string what)
        {
            return new CompactException("compact_bad_layout", "malformed JSON at character " + at + ": " + what);
        }

        private static void SkipSpace(string s, ref int at)
        {
            while (at < s.Length && (s[at] == ' ' || s[at] == '\t' || s[at] == '\n' || s[at] == '\r')) at++;
        }

        private static object ReadValue(string s, ref int at, int depth)
        {
            if (depth > MaxDepth) throw Bad(at, "nested more than " + MaxDepth + " deep");
            SkipSpace(s, ref at);
            if (at >= s.Length) throw Bad(at, "the text ends before a value");
            char c = s[at];
            if (c == '{') return ReadObject(s, ref at, depth);
            if (c == '[') return ReadArray(s, ref at, depth);
            if (c == '"') return ReadString(s, ref at);
            if (c == '-' || (c >= '0' && c <= '9')) return ReadNumber(s, ref at);
            if (Word(s, ref at, "true")) return true;
            if (Word(s, ref at, "false")) return false;
            if (Word(s, ref at, "null")) return null;
            throw Bad(at, "unexpected '" + c + "'");
        }

        private static bool Word(string s, ref int at, string word)
        {
            if (string.CompareOrdinal(s, at, word, 0, word.Length) != 0) return false;
            at += word.Length;
            return true;
        }

        private static Dictionary<string, object> ReadObject(string s, ref int at, int depth)
        {
            var o = new Dictionary<string, object>();
            at++;
            SkipSpace(s, ref at);
            if (at < s.Length && s[at] == '}')
            {
                at++;
                return o;
            }
            while (true)
            {
                SkipSpace(s, ref at);
                if (at >= s.Length || s[at] != '"') throw Bad(at, "expected a member name");
                var name = ReadString(s, ref at);
                SkipSpace(s, ref at);
                if (at >= s.Length || s[at] != ':') throw Bad(at, "expected ':'");
                at++;
                o[name] = ReadValue(s, ref at, depth + 1);
                SkipSpace(s, ref at);
                if (at < s.Length && s[at] == ',')
                {
                    at++;
                    continue;
                }
                if (at < s.Length && s[at] == '}')
                {
                    at++;
                    return o;
                }
                throw Bad(at, "expected ',' or '}'");
            }
        }

        private static List<object> ReadArray(string s, ref int at, int depth)
        {
            var list = new List<object>();
            at++;
            SkipSpace(s, ref at);
            if (at < s.Length && s[at] == ']')
            {
                at++;
                return list;
            }
            while (true)
            {
                list.Add(ReadValue(s, ref at, depth + 1));
                SkipSpace(s, ref at);
                if (at < s.Length && s[at] == ',')
                {
                    at++;
                    continue;
                }
                if (at < s.Length && s[at] == ']')
                {
                    at++;
                    return list;
                }
                throw Bad(at, "expected ',' or ']'");
            }
        }

        private static string ReadString(string s, ref int at)
        {
            var sb = new StringBuilder();
            at++;
            while (at < s.Length)
            {
                char c = s[at++];
                if (c == '"') return sb.ToString();
                if (c != '\\')
                {
                    sb.Append(c);
                    continue;
                }
                if (at >= s.Length) break;
                char e = s[at++];
                switch (e)
                {
                    case '"': sb.Append('"'); break;
                    case '\\': sb.Append('\\'); break;
                    case '/': sb.Append('/'); break;
                    case 'b': sb.Append('\b'); break;
                    case 'f': sb.Append('\f'); break;
                    case 'n': sb.Append('\n'); break;
                    case 'r': sb.Append('\r'); break;
                    case 't': sb.Append('\t'); break;
                    case 'u':
                        int code;
                        if (at + 4 > s.Length || !int.TryParse(s.Substring(at, 4), NumberStyles.AllowHexSpecifier, CultureInfo.InvariantCulture, out code))
                        {
                            throw Bad(at, "a \\u escape without four hex digits");
                        }
                        sb.Append((char)code);
                        at += 4;
                        break;
                    default:
                        throw Bad(at - 1, "unknown escape '\\" + e + "'");
                }
            }
            throw Bad(at, "the text ends inside a string");
        }

        private static double ReadNumber(string s, ref int at)
        {
            int start = at;
            while (at < s.Length && "+-0123456789.eE".IndexOf(s[at]) >= 0) at++;
            double d;
            if (!double.TryParse(s.Substring(start, at - start), NumberStyles.Float, CultureInfo.InvariantCulture, out d))
            {
                throw Bad(start, "a malformed number");
            }
            return d;
        }
    }
}
