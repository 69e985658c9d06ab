# Compresses the chunks of a drivecheck recording (`campaign.mcap`) again with each candidate
# compression and prints their bytes and the compression's CPU time (one thread); the rest of the
# file (message indexes, chunk headers, summary) is the same whatever the compression.
# docs/recording.md, "Size and speed".
#
#   pip install mcap zstandard lz4
#   drivecheck run --seed 1 --tests 300 --jobs 2 --record all --out /tmp/r
#   python3 benches/recording/compressors.py /tmp/r/campaign.mcap 300
import sys, time, os
import zstandard, lz4.frame
from mcap.stream_reader import StreamReader
from mcap.records import Chunk

path = sys.argv[1]; tests = int(sys.argv[2])
chunks = []
sum_now = 0
with open(path, 'rb') as f:
    for record in StreamReader(f, skip_magic=False, emit_chunks=True).records:
        if isinstance(record, Chunk):
            assert record.compression == 'zstd'
            sum_now += len(record.data)
            chunks.append(zstandard.ZstdDecompressor().decompress(
                record.data, max_output_size=record.uncompressed_size))
raw = sum(len(c) for c in chunks)
size = os.path.getsize(path)
cands = [('none', lambda c: c)]
for level in (1, 3, 6, 9, 19):
    z = zstandard.ZstdCompressor(level=level)
    cands.append((f'zstd-{level}', z.compress))
cands.append(('lz4', lambda c: lz4.frame.compress(c)))
cands.append(('lz4-hc9', lambda c: lz4.frame.compress(c, compression_level=9)))
print(f'{len(chunks)} chunks, {raw/1e6:.1f} MB uncompressed, file {size/1e6:.1f} MB, {tests} tests')
for name, fn in cands:
    t0 = time.process_time()
    total = sum(len(fn(c)) for c in chunks)
    dt = time.process_time() - t0
    rest = size - sum_now
    print(f'{name:8} {total/1e6:8.2f} MB  {(rest + total)/tests/1e6:6.3f} MB a test  '
          f'{dt:6.2f} s CPU  {raw/1e6/max(dt,1e-9):7.0f} MB/s')
