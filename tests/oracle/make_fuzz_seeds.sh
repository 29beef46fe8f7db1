#!/usr/bin/env bash
# Regenerates the seed corpora of tests/fuzz/fuzz_spz and fuzz_compressed_ply: small random
# graphdeco PLYs (SH degree 0..3; 3 Gaussians, and 300 so that compressed PLY has two chunks)
# converted by splat-transform (tests/oracle/install-deps.sh first). Deterministic seeds.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../.." && pwd)
st=$here/node_modules/.bin/splat-transform
[ -x "$st" ] || { echo "make_fuzz_seeds: run tests/oracle/install-deps.sh first" >&2; exit 2; }
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
spz=$root/tests/fuzz/corpus/fuzz_spz
cply=$root/tests/fuzz/corpus/fuzz_compressed_ply
mkdir -p "$spz" "$cply"
for degree in 0 1 2 3; do
  for count in 3 300; do
    [ "$count" = 300 ] && [ "$degree" -gt 1 ] && continue  # keep each seed a few KB
    python3 - "$work/in.ply" "$degree" "$count" <<'PY'
import math, random, struct, sys
path, degree, count = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
rng = random.Random(degree * 1000 + count)
rest = 3 * ((degree + 1) ** 2 - 1)
names = ['x', 'y', 'z', 'f_dc_0', 'f_dc_1', 'f_dc_2'] + ['f_rest_%d' % i for i in range(rest)] + \
        ['opacity', 'scale_0', 'scale_1', 'scale_2', 'rot_0', 'rot_1', 'rot_2', 'rot_3']
with open(path, 'wb') as f:
    f.write(('ply\nformat binary_little_endian 1.0\nelement vertex %d\n' % count).encode())
    f.write(''.join('property float %s\n' % n for n in names).encode() + b'end_header\n')
    for _ in range(count):
        q = [rng.gauss(0, 1) for _ in range(4)]
        n = math.sqrt(sum(c * c for c in q))
        row = [rng.uniform(-5, 5), rng.uniform(-3, 3), rng.uniform(1, 9)] + \
              [rng.uniform(-1.5, 1.5) for _ in range(3)] + [rng.uniform(-0.4, 0.4) for _ in range(rest)] + \
              [rng.uniform(-3, 5)] + [rng.uniform(-5, -1) for _ in range(3)] + [c / n for c in q]
        f.write(struct.pack('<%df' % len(row), *row))
PY
    "$st" -q -w "$work/in.ply" --spz-version 3 "$spz/seed_sh${degree}_n${count}.spz"
    "$st" -q -w "$work/in.ply" "$cply/seed_sh${degree}_n${count}.compressed.ply"
  done
done
# The inflated payloads (fuzz_spz also gzips its input), and version 2 copies of the small
# ones: splat-transform writes only versions 3 and 4, so the rotations are re-encoded here.
python3 - "$spz" <<'PY'
import glob, gzip, math, struct, sys
for path in sorted(glob.glob(sys.argv[1] + '/seed_*.spz')):
    raw = gzip.open(path).read()
    open(path + '.raw', 'wb').write(raw)
    _, _, n, degree, _, _, _ = struct.unpack('<IIIBBBB', raw[:16])
    if n > 3:
        continue
    rot = 16 + n * (9 + 1 + 3 + 3)
    v2 = bytearray(raw[:rot])
    struct.pack_into('<I', v2, 4, 2)
    for i in range(n):
        bits = struct.unpack('<I', raw[rot + 4 * i:rot + 4 * i + 4])[0]
        largest, q, norm2 = bits >> 30, [0.0] * 4, 0.0
        for c in (3, 2, 1, 0):
            if c == largest:
                continue
            mag = math.sqrt(0.5) * (bits & 511) / 511
            q[c] = -mag if (bits >> 9) & 1 else mag
            norm2 += q[c] * q[c]
            bits >>= 10
        q[largest] = math.sqrt(max(0.0, 1 - norm2))
        sign = -1.0 if q[3] < 0 else 1.0
        v2 += bytes(min(255, max(0, round(127.5 * (1 + sign * c)))) for c in q[:3])
    v2 += raw[rot + 4 * n:]
    open(path.replace('.spz', '_v2.spz.raw'), 'wb').write(bytes(v2))
PY
ls -l "$spz" "$cply"
