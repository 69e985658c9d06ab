# What a test of a recording would cost without some channels, or with only every k-th message of
# the high-rate ones: rewrites a drivecheck recording (`campaign.mcap`) with the Python `mcap`
# writer (zstd chunks of 256 KiB with message indexes, as drivecheck writes them) once per
# variant and prints messages and MB a test. docs/recording.md, "Size and speed".
#
#   pip install mcap zstandard
#   drivecheck run --seed 1 --tests 100 --jobs 2 --record all --out /tmp/r
#   python3 benches/recording/variants.py /tmp/r/campaign.mcap 100
import collections
import os
import sys
import tempfile

from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

HIGH = ['/car/state', '/sim/truth', '/foxglove/rtk', '/foxglove/uwb', '/sim/ranges']
POSES = ('/foxglove/rtk', '/foxglove/uwb')


def variant(src, tests, name, keep):
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, 'variant.mcap')
        with open(src, 'rb') as f, open(out, 'wb') as o:
            reader = make_reader(f)
            writer = Writer(o, chunk_size=256 * 1024, compression=CompressionType.ZSTD)
            writer.start(profile='', library='variants')
            schemas, channels, counts = {}, {}, collections.Counter()
            kept = 0
            for schema, channel, message in reader.iter_messages(log_time_order=False):
                counts[channel.topic] += 1
                if not keep(channel.topic, counts[channel.topic]):
                    continue
                if schema is not None and schema.id not in schemas:
                    schemas[schema.id] = writer.register_schema(
                        schema.name, schema.encoding, schema.data)
                if channel.id not in channels:
                    channels[channel.id] = writer.register_channel(
                        channel.topic, channel.message_encoding,
                        schemas.get(channel.schema_id, 0))
                writer.add_message(channels[channel.id], message.log_time, message.data,
                                   message.publish_time, message.sequence)
                kept += 1
            writer.finish()
        size = os.path.getsize(out)
    print(f'{name:48s} {kept / tests:7.0f} messages a test {size / tests / 1e6:6.3f} MB a test')


def main():
    src, tests = sys.argv[1], int(sys.argv[2])
    sim = lambda t: t.startswith('/sim/')
    variants = [
        ('as it is', lambda t, k: True),
        ('without /sim/truth and /sim/ranges', lambda t, k: t not in ('/sim/truth', '/sim/ranges')),
        ('without the two pose channels', lambda t, k: t not in POSES),
        ('/sim/* at 5 Hz, what the car sent at 20 Hz', lambda t, k: not sim(t) or k % 4 == 0),
        ('the five high-rate channels at 10 Hz', lambda t, k: t not in HIGH or k % 2 == 0),
        ('the five high-rate channels at 5 Hz', lambda t, k: t not in HIGH or k % 4 == 0),
        ('without /sim/*, what the car sent at 10 Hz',
         lambda t, k: not sim(t) and (t not in HIGH or k % 2 == 0)),
        ('without /sim/*, /car/state 20 Hz, poses 10 Hz',
         lambda t, k: not sim(t) and (t not in POSES or k % 2 == 0)),
    ]
    for name, keep in variants:
        variant(src, tests, name, keep)


if __name__ == '__main__':
    main()
