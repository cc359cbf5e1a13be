// Times the C# compact decoder on the 71-joint test vector (docs/compact-frames/chain71.json), a key frame and a
// delta frame alternately, as examples/clients/js/compact-bench.mjs times the JavaScript one; and counts the
// garbage collections the decoding caused (none: it decodes into one frame's arrays).
//
//   mcs -optimize+ -out:/tmp/bench.exe examples/clients/csharp/Compact.cs examples/clients/csharp/CompactBench.cs
//   mono /tmp/bench.exe docs/compact-frames/chain71.json

using System;
using System.Collections.Generic;
using System.Diagnostics;
using System.Globalization;
using System.IO;
using System.Linq;

using Inbetween;

static class CompactBench
{
    static int Main(string[] args)
    {
        var vector = (Dictionary<string, object>)CompactJson.Parse(File.ReadAllText(args.Length > 0 ? args[0] : "docs/compact-frames/chain71.json"));
        var decoder = new CompactDecoder(CompactLayout.FromJson(vector["layout"]));
        var frame = decoder.NewFrame();
        var bytes = ((List<object>)vector["frames"]).Select(f => Hex((string)((Dictionary<string, object>)f)["hex"])).ToArray();
        Func<int, double> run = frames =>
        {
            var clock = Stopwatch.StartNew();
            for (int i = 0; i < frames; i++)
            {
                decoder.Decode(bytes[0], frame);
                decoder.Decode(bytes[1], frame);
            }
            return clock.Elapsed.TotalMilliseconds * 1000 / (2 * frames);
        };
        run(20000); // warm up the JIT
        int collections = GC.CollectionCount(0);
        var samples = Enumerable.Range(0, 5).Select(_ => run(50000)).OrderBy(x => x).ToArray();
        collections = GC.CollectionCount(0) - collections;
        Console.WriteLine(
            "{0} joints, {1} B key / {2} B delta: {3:F2} µs per frame (median of 5 runs of 100,000 frames; min {4:F2}); {5} collections",
            decoder.JointCount, bytes[0].Length, bytes[1].Length, samples[2], samples[0], collections);
        return 0;
    }

    static byte[] Hex(string hex)
    {
        var bytes = new byte[hex.Length / 2];
        for (int i = 0; i < bytes.Length; i++) bytes[i] = byte.Parse(hex.Substring(2 * i, 2), NumberStyles.HexNumber);
        return bytes;
    }
}
