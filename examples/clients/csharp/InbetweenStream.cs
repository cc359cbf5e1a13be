// Plays an inbetween compact stream (docs/compact-frames.md) on a Unity
// Transform hierarchy: each joint's local translation, rotation and scale onto
// the Transform of the same name under `root`, no Animator.
//
// Three parts, the first two plain C# (Mono compiles and tests them without Unity):
// - UnityAxes: the glTF → Unity axis conversion of a decoded pose, in place.
// - CompactStreamClient: opens the WebSocket (System.Net.WebSockets), reads the
//   `opened` message's layout (and a new layout mid-stream, `{"layout", "seq"}`),
//   decodes every frame off the game thread and keeps the newest, and every
//   event crossed, for the game thread to take.
// - InbetweenStream (Unity only, under UNITY_5_3_OR_NEWER): the MonoBehaviour.
//   Add it to a character, set `clip`, and the skeleton moves with the stream.
//
// The stream is in local space (compact frames always are), which is what a
// Transform's localPosition / localRotation / localScale hold.

using System;
using System.Collections.Generic;
using System.Globalization;
using System.Net.WebSockets;
using System.Text;
using System.Threading;
using System.Threading.Tasks;

namespace Inbetween
{
    /// <summary>How the stream's axes map onto the engine's.</summary>
    public enum AxisConversion
    {
        /// <summary>
        /// glTF (right-handed, Y up, +Z forward) to Unity (left-handed, Y up, +Z forward) by mirroring X, as glTFast
        /// and UnityGLTF import models: translations (−x, y, z), rotations (x, −y, −z, w), scales unchanged.
        /// </summary>
        GltfToUnity,
        /// <summary>
        /// glTF to Unity by mirroring Z, as UniGLTF and UniVRM import models: translations (x, y, −z), rotations
        /// (−x, −y, z, w), scales unchanged.
        /// </summary>
        GltfToUnityMirrorZ,
        /// <summary>The values as they are (a rig imported without the conversion, or a right-handed engine).</summary>
        None,
    }

    /// <summary>
    /// The axis conversion of a decoded local pose. Mirroring axis k is the change of basis S (the identity with
    /// −1 at k); a local transform p' = T + R·p becomes S·p' = S·T + (S·R·S)·(S·p), so T goes to S·T and R to
    /// S·R·S. A rotation by angle θ about axis a, conjugated by a reflection, is the rotation by θ about
    /// det(S)·S·a = −S·a: the quaternion's vector part negated except at k (X: (x, −y, −z, w)). Scales along the
    /// local axes are unchanged.
    /// </summary>
    public static class UnityAxes
    {
        /// <summary>Converts the first <paramref name="joints"/> joints of a pose's arrays in place.</summary>
        public static void Convert(AxisConversion conversion, float[] translations, float[] rotations, int joints)
        {
            if (conversion == AxisConversion.None) return;
            int k = conversion == AxisConversion.GltfToUnity ? 0 : 2;
            for (int j = 0; j < joints; j++)
            {
                translations[3 * j + k] = -translations[3 * j + k];
                for (int c = 0; c < 3; c++)
                {
                    if (c != k) rotations[4 * j + c] = -rotations[4 * j + c];
                }
            }
        }

        /// <summary>
        /// Converts a root motion report's [x, y, z, yaw] in place: the translation as a joint's, and the yaw about
        /// +Y negated (a mirror's conjugation negates the quaternion's y, as in Convert).
        /// </summary>
        public static void ConvertRootMotion(AxisConversion conversion, float[] xyzYaw)
        {
            if (conversion == AxisConversion.None) return;
            int k = conversion == AxisConversion.GltfToUnity ? 0 : 2;
            xyzYaw[k] = -xyzYaw[k];
            xyzYaw[3] = -xyzYaw[3];
        }

        /// <summary>
        /// The rotation by <paramref name="yaw"/> radians about +Y, then <paramref name="q"/> [x, y, z, w] under it:
        /// (0, sin(yaw/2), 0, cos(yaw/2)) · q, as [x, y, z, w].
        /// </summary>
        public static float[] YawThen(float yaw, float[] q)
        {
            float s = (float)Math.Sin(yaw / 2), c = (float)Math.Cos(yaw / 2);
            return new[] { c * q[0] + s * q[2], c * q[1] + s * q[3], c * q[2] - s * q[0], c * q[3] - s * q[1] };
        }
    }

    /// <summary>An event a frame crossed (docs/compact-frames.md): its name in the layout, and the frame's seq.</summary>
    public struct CrossedEvent
    {
        public string Name;
        public ulong Seq;
    }

    /// <summary>
    /// A compact stream's WebSocket: <c>GET /v1/clips/{id}/stream</c> or <c>GET /v1/broadcasts/{id}/stream</c> with
    /// <c>encoding=compact</c>. Frames are read and decoded on a background task; the game thread takes the newest
    /// with TryTakeNewest (a game renders at its own rate, so frames it did not take are skipped, but every frame is
    /// decoded: a delta frame needs its key frame).
    /// </summary>
    public sealed class CompactStreamClient : IDisposable
    {
        private readonly Uri uri;
        private readonly string token;
        private readonly ClientWebSocket socket = new ClientWebSocket();
        private readonly CancellationTokenSource stop = new CancellationTokenSource();
        private readonly SemaphoreSlim sending = new SemaphoreSlim(1, 1);
        private readonly object gate = new object();
        private volatile CompactDecoder decoder;
        private CompactFrame decoded;
        private CompactFrame newest;
        private bool fresh;
        private long framesDecoded;
        // Every event crossed since the game thread last took them (at most MaxEvents: the oldest go first).
        private readonly Queue<CrossedEvent> crossed = new Queue<CrossedEvent>();
        private const int MaxEvents = 1024;
        private volatile string error;
        private volatile bool finished;
        private Task run;

        /// <param name="uri">The stream's address, e.g. from ClipUri.</param>
        /// <param name="token">A read token (Authorization: Bearer), or null.</param>
        public CompactStreamClient(Uri uri, string token)
        {
            this.uri = uri;
            this.token = token;
        }

        /// <summary>
        /// <c>{server}/v1/clips/{clip}/stream?fps=…&amp;encoding=compact</c>, with <c>max_error</c> and
        /// <c>distance</c> when above 0 (0: the server's defaults, docs/compact-frames.md "The error bound").
        /// <paramref name="clip"/> is a clip id (an upload answers it; <c>GET /v1/clips</c> lists them).
        /// </summary>
        public static Uri ClipUri(string server, string clip, int fps, double maxError, double distance)
        {
            return StreamUri(server, "/v1/clips/" + Uri.EscapeDataString(clip) + "/stream", "fps=" + fps, maxError, distance);
        }

        /// <summary><c>{server}/v1/broadcasts/{id}/stream?encoding=compact</c>: a shared playback, watched.</summary>
        public static Uri BroadcastUri(string server, string broadcast, double maxError, double distance)
        {
            return StreamUri(server, "/v1/broadcasts/" + Uri.EscapeDataString(broadcast) + "/stream", null, maxError, distance);
        }

        private static Uri StreamUri(string server, string path, string first, double maxError, double distance)
        {
            var query = new StringBuilder(first == null ? "encoding=compact" : first + "&encoding=compact");
            if (maxError > 0) query.Append("&max_error=").Append(maxError.ToString("R", CultureInfo.InvariantCulture));
            if (distance > 0) query.Append("&distance=").Append(distance.ToString("R", CultureInfo.InvariantCulture));
            return new Uri(server.TrimEnd('/') + path + "?" + query);
        }

        /// <summary>
        /// The stream's decoder once the `opened` message has come (null before), for its Layout, Names and
        /// NewFrame(); the client's task decodes with it, so never call its Decode.
        /// </summary>
        public CompactDecoder Decoder
        {
            get { return decoder; }
        }

        /// <summary>The last thing that went wrong (a refusal's code and detail, a malformed frame), or null.</summary>
        public string Error
        {
            get { return error; }
        }

        /// <summary>The socket has closed (see CloseStatus) or failed (see Error).</summary>
        public bool Finished
        {
            get { return finished; }
        }

        public WebSocketCloseStatus? CloseStatus
        {
            get { return socket.CloseStatus; }
        }

        public string CloseDescription
        {
            get { return socket.CloseStatusDescription; }
        }

        public long FramesDecoded
        {
            get { return Interlocked.Read(ref framesDecoded); }
        }

        /// <summary>Connects and starts reading; the returned task ends when the stream does.</summary>
        public Task Start()
        {
            if (run != null) throw new InvalidOperationException("the stream has already started");
            if (!string.IsNullOrEmpty(token)) socket.Options.SetRequestHeader("Authorization", "Bearer " + token);
            run = Task.Run(() => RunAsync(stop.Token));
            return run;
        }

        /// <summary>
        /// Copies the newest decoded frame not yet taken into <paramref name="into"/> (from Decoder.NewFrame());
        /// false when no new frame has come since the last call.
        /// </summary>
        public bool TryTakeNewest(CompactFrame into)
        {
            lock (gate)
            {
                if (!fresh) return false;
                Copy(newest, into);
                fresh = false;
                return true;
            }
        }

        /// <summary>
        /// Moves every event crossed since the last call into <paramref name="into"/>, in the order crossed (events
        /// of frames TryTakeNewest skipped too); returns how many.
        /// </summary>
        public int TakeEvents(List<CrossedEvent> into)
        {
            lock (gate)
            {
                int n = crossed.Count;
                while (crossed.Count > 0) into.Add(crossed.Dequeue());
                return n;
            }
        }

        /// <summary>Sends a control (docs/api.md, "Streams"), e.g. <c>{"op":"seek","time":1.5}</c>; it acts on the next tick.</summary>
        public async Task SendAsync(string control)
        {
            var bytes = new ArraySegment<byte>(Encoding.UTF8.GetBytes(control));
            await sending.WaitAsync(stop.Token).ConfigureAwait(false);
            try
            {
                await socket.SendAsync(bytes, WebSocketMessageType.Text, true, stop.Token).ConfigureAwait(false);
            }
            finally
            {
                sending.Release();
            }
        }

        /// <summary>SendAsync without waiting: a failure to send shows in Error.</summary>
        public void Send(string control)
        {
            SendAsync(control).ContinueWith(
                t => error = "sending a control: " + t.Exception.GetBaseException().Message,
                TaskContinuationOptions.OnlyOnFaulted);
        }

        /// <summary>
        /// Closes the stream (1000) if it is open, and stops reading; returns at once (the game thread never waits on
        /// the network).
        /// </summary>
        public void Dispose()
        {
            if (socket.State != WebSocketState.Open)
            {
                stop.Cancel();
                return;
            }
            socket.CloseOutputAsync(WebSocketCloseStatus.NormalClosure, "done", CancellationToken.None)
                .ContinueWith(_ => stop.Cancel(), TaskScheduler.Default);
        }

        private async Task RunAsync(CancellationToken cancel)
        {
            try
            {
                await socket.ConnectAsync(uri, cancel).ConfigureAwait(false);
                var buffer = new byte[4096];
                while (socket.State == WebSocketState.Open)
                {
                    int length = 0;
                    WebSocketReceiveResult result;
                    do
                    {
                        if (length == buffer.Length) Array.Resize(ref buffer, buffer.Length * 2);
                        result = await socket.ReceiveAsync(new ArraySegment<byte>(buffer, length, buffer.Length - length), cancel).ConfigureAwait(false);
                        length += result.Count;
                    } while (!result.EndOfMessage);
                    if (result.MessageType == WebSocketMessageType.Close)
                    {
                        await AnswerClose().ConfigureAwait(false);
                        break;
                    }
                    if (result.MessageType == WebSocketMessageType.Text) OnText(Encoding.UTF8.GetString(buffer, 0, length));
                    else OnFrame(buffer, length);
                }
            }
            catch (OperationCanceledException)
            {
                // Disposed.
            }
            catch (Exception e)
            {
                error = e.GetType().Name + ": " + e.Message;
            }
            finally
            {
                finished = true;
            }
        }

        // The server closed (a stop, max_frames, shutdown): answer with the same code, as the protocol asks.
        private async Task AnswerClose()
        {
            if (socket.State != WebSocketState.CloseReceived) return;
            try
            {
                await socket.CloseOutputAsync(socket.CloseStatus ?? WebSocketCloseStatus.NormalClosure, "", CancellationToken.None).ConfigureAwait(false);
            }
            catch (WebSocketException)
            {
                // The server has already gone: the close is complete from its side.
            }
        }

        // The `opened` message (the layout), a new layout mid-stream (docs/compact-frames.md, "A new layout": the
        // frames after it, from a key frame, are in it) or an `error` (a control refused; the stream goes on).
        internal void OnText(string text)
        {
            var message = CompactJson.Parse(text) as Dictionary<string, object>;
            object value;
            if (message != null && message.TryGetValue("layout", out value) && decoder != null)
            {
                // The skeleton is the stream's: the frames the game thread holds still fit.
                decoder.Relayout(CompactLayout.FromJson(value));
            }
            else if (message != null && message.TryGetValue("opened", out value))
            {
                var opened = value as Dictionary<string, object>;
                object layout;
                if (opened == null || !opened.TryGetValue("compact", out layout))
                {
                    error = "the opened message has no compact layout: is encoding=compact in the address?";
                    return;
                }
                var d = new CompactDecoder(CompactLayout.FromJson(layout));
                decoded = d.NewFrame();
                newest = d.NewFrame();
                decoder = d;
            }
            else if (message != null && message.TryGetValue("error", out value))
            {
                error = CompactJson.Show(value);
                var refusal = value as Dictionary<string, object>;
                object code, detail;
                if (refusal != null && refusal.TryGetValue("code", out code) && refusal.TryGetValue("detail", out detail))
                {
                    error = code + ": " + detail;
                }
            }
        }

        internal void OnFrame(byte[] bytes, int length)
        {
            var d = decoder;
            if (d == null)
            {
                error = "a binary frame came before the opened message";
                return;
            }
            try
            {
                d.Decode(bytes, 0, length, decoded);
            }
            catch (CompactException e)
            {
                error = e.Message;
                return;
            }
            Interlocked.Increment(ref framesDecoded);
            lock (gate)
            {
                Copy(decoded, newest);
                fresh = true;
                // Named now: a later layout may list other events.
                var names = d.Layout.EventNames;
                for (int i = 0; i < decoded.EventCount; i++)
                {
                    if (crossed.Count == MaxEvents) crossed.Dequeue();
                    crossed.Enqueue(new CrossedEvent { Name = names[decoded.Events[i]], Seq = decoded.Seq });
                }
            }
        }

        private static void Copy(CompactFrame from, CompactFrame to)
        {
            to.Key = from.Key;
            to.Seq = from.Seq;
            to.Dropped = from.Dropped;
            to.KeySeq = from.KeySeq;
            to.SentAtUnixNanos = from.SentAtUnixNanos;
            to.ClipTime = from.ClipTime;
            to.JointsSent = from.JointsSent;
            Array.Copy(from.Translations, to.Translations, from.Translations.Length);
            Array.Copy(from.Rotations, to.Rotations, from.Rotations.Length);
            Array.Copy(from.Scales, to.Scales, from.Scales.Length);
            to.HasRootMotion = from.HasRootMotion;
            Array.Copy(from.RootMotion, to.RootMotion, from.RootMotion.Length);
            to.HasGraph = from.HasGraph;
            if (from.HasGraph) to.GraphStore.CopyFrom(from.GraphStore);
        }
    }
}

#if UNITY_5_3_OR_NEWER
namespace Inbetween
{
    using UnityEngine;

    /// <summary>
    /// Streams a clip (or watches a broadcast) in compact frames and poses the Transforms under <see cref="root"/>
    /// whose names are the stream's joint names. Needs the .NET 4.x / .NET Standard 2.1 API level
    /// (System.Net.WebSockets); not WebGL, whose sockets are the browser's.
    /// </summary>
    public sealed class InbetweenStream : MonoBehaviour
    {
        [Tooltip("The server's WebSocket address")]
        public string server = "ws://127.0.0.1:8080";
        [Tooltip("A clip id (an upload answers it; GET /v1/clips lists them)")]
        public string clip = "";
        [Tooltip("A broadcast id to watch instead of a clip")]
        public string broadcast = "";
        [Tooltip("Frames a second, 1 to 240 (clips only: a broadcast has its own rate)")]
        public int fps = 60;
        [Tooltip("The error bound in metres; 0: the server's default, 1e-4")]
        public float maxError;
        [Tooltip("The bound's distance in metres; 0: the server's default, 10 % of the rest height")]
        public float distance;
        [Tooltip("A read token, if the server has tokens configured")]
        public string token = "";
        [Tooltip("The top of the hierarchy searched for joints by name; this object when empty")]
        public Transform root;
        [Tooltip("GltfToUnity for models imported by glTFast or UnityGLTF (X mirrored), GltfToUnityMirrorZ for UniGLTF and UniVRM")]
        public AxisConversion axes = AxisConversion.GltfToUnity;
        [Tooltip("Move this object by the stream's root motion (its total since the stream began), on top of where it was placed")]
        public bool applyRootMotion = true;

        /// <summary>
        /// Raised on the game thread, in Update, for every event the stream's frames crossed since the last Update
        /// (its name in the clip, and the frame's seq), in the order crossed: footsteps, sound cues.
        /// </summary>
        public event Action<string, ulong> EventCrossed;

        private CompactStreamClient client;
        private CompactFrame frame;
        private Transform[] targets;
        private string reported;
        private readonly List<CrossedEvent> events = new List<CrossedEvent>();
        private readonly float[] rootMotion = new float[4];
        // Where this object was when the stream started: root motion is added to it.
        private Vector3 originPosition;
        private float[] originRotation;

        /// <summary>The newest frame applied (its seq, dropped, clip time), or null before the first.</summary>
        public CompactFrame Frame
        {
            get { return targets == null ? null : frame; }
        }

        private void OnEnable()
        {
            var uri = string.IsNullOrEmpty(broadcast)
                ? CompactStreamClient.ClipUri(server, clip, fps, maxError, distance)
                : CompactStreamClient.BroadcastUri(server, broadcast, maxError, distance);
            client = new CompactStreamClient(uri, token);
            client.Start();
            originPosition = transform.localPosition;
            var q = transform.localRotation;
            originRotation = new[] { q.x, q.y, q.z, q.w };
        }

        private void OnDisable()
        {
            client.Dispose();
            client = null;
            targets = null;
        }

        private void Update()
        {
            var decoder = client.Decoder;
            if (decoder != null && targets == null) Bind(decoder);
            if (targets != null && client.TryTakeNewest(frame)) Apply();
            RaiseEvents();
            var error = client.Error;
            if (error != null && error != reported)
            {
                Debug.LogWarning("inbetween: " + error, this);
                reported = error;
            }
        }

        // Joints are matched to Transforms by name once, when the layout arrives; the first of a repeated name wins.
        private void Bind(CompactDecoder decoder)
        {
            var byName = new Dictionary<string, Transform>();
            foreach (var t in (root != null ? root : transform).GetComponentsInChildren<Transform>(true))
            {
                if (!byName.ContainsKey(t.name)) byName.Add(t.name, t);
            }
            var names = decoder.Names;
            targets = new Transform[names.Length];
            var missing = new List<string>();
            for (int j = 0; j < names.Length; j++)
            {
                if (!byName.TryGetValue(names[j], out targets[j])) missing.Add(names[j]);
            }
            if (missing.Count > 0)
            {
                Debug.LogWarning("inbetween: no Transform named " + string.Join(", ", missing.ToArray()) + "; those joints are skipped", this);
            }
            frame = decoder.NewFrame();
        }

        private void Apply()
        {
            var t = frame.Translations;
            var r = frame.Rotations;
            var s = frame.Scales;
            UnityAxes.Convert(axes, t, r, targets.Length);
            for (int j = 0; j < targets.Length; j++)
            {
                var target = targets[j];
                if (target == null) continue;
                target.localPosition = new Vector3(t[3 * j], t[3 * j + 1], t[3 * j + 2]);
                target.localRotation = new Quaternion(r[4 * j], r[4 * j + 1], r[4 * j + 2], r[4 * j + 3]);
                target.localScale = new Vector3(s[3 * j], s[3 * j + 1], s[3 * j + 2]);
            }
            if (applyRootMotion && frame.HasRootMotion) ApplyRootMotion();
        }

        // As the three.js player: the total travelled on top of the placement, the yaw turned before it.
        private void ApplyRootMotion()
        {
            Array.Copy(frame.RootMotion, 4, rootMotion, 0, 4);
            UnityAxes.ConvertRootMotion(axes, rootMotion);
            var p = originPosition;
            transform.localPosition = new Vector3(p.x + rootMotion[0], p.y + rootMotion[1], p.z + rootMotion[2]);
            var q = UnityAxes.YawThen(rootMotion[3], originRotation);
            transform.localRotation = new Quaternion(q[0], q[1], q[2], q[3]);
        }

        private void RaiseEvents()
        {
            events.Clear();
            if (client.TakeEvents(events) == 0 || EventCrossed == null) return;
            foreach (var e in events) EventCrossed(e.Name, e.Seq);
        }

        /// <summary>
        /// Controls act on the server's next tick (docs/api.md, "Streams"). Not on a broadcast watched: its controls go
        /// to <c>POST /v1/broadcasts/{id}/controls</c> (docs/broadcasts.md).
        /// </summary>
        public void Seek(float time)
        {
            Send("{\"op\":\"seek\",\"time\":" + time.ToString("R", CultureInfo.InvariantCulture) + "}");
        }

        public void SetSpeed(float speed)
        {
            Send("{\"op\":\"speed\",\"speed\":" + speed.ToString("R", CultureInfo.InvariantCulture) + "}");
        }

        public void Pause()
        {
            Send("{\"op\":\"pause\"}");
        }

        public void Play()
        {
            Send("{\"op\":\"play\"}");
        }

        private void Send(string control)
        {
            if (client != null) client.Send(control);
        }
    }
}
#endif
