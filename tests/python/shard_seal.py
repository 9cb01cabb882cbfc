"""A dataset shard's header computed from its description alone (ui/dataset/shard.h),
for tests and the Python fuzzer that need shards with sound headers over chosen bytes."""


def sealed(body, shard=0, spec_digest=0):
    """A shard's 512-byte header over `body` (the bytes after it), as ui/dataset/shard.h
    describes it, computed here from that description: splitmix64's finaliser over the
    little-endian 8-byte words of the file after the header, its tail byte by byte, then
    its length."""
    mask = (1 << 64) - 1

    def mix(x):
        x = (x + 0x9E3779B97F4A7C15) & mask
        x = ((x ^ (x >> 30)) * 0xBF58476D1CE4E5B9) & mask
        x = ((x ^ (x >> 27)) * 0x94D049BB133111EB) & mask
        return x ^ (x >> 31)

    whole = bytes(512) + body
    h, at = 0x73686172642D6331, 512
    while at + 8 <= len(whole):
        h = mix(h ^ int.from_bytes(whole[at:at + 8], "little"))
        at += 8
    for b in whole[at:]:
        h = mix(h ^ b)
    h = mix(h ^ len(whole))
    header = (f"sonotrace shard\nspec_digest {spec_digest:016x}\nshard {shard}\n"
              f"content_checksum {h:016x}\n").encode()
    return header + bytes(512 - len(header)) + body
