#!/usr/bin/python3
"""Every struct of idl/Surgsim.idl is annotated @final (the wire format is XCDR1, final: another vendor's generator
must not guess its extensibility), and the only keys are the `instrument` members of the per-instrument streams
(ToolCommand, ForceFeedback: several instruments, since wire version v2) and the `organ` of the per-organ BodyState
(several organs, wire version v3). Every sequence and string is bounded (samples are preallocated). The web view's Frame is keyless and its JPEG payload a bounded sequence<octet, N>.
Usage: check_idl_final.py IDL_FILE"""
import re
import sys

path = sys.argv[1]
text = open(path, encoding='utf-8').read()
lines = text.splitlines()
bad = []
structs = 0
for i, line in enumerate(lines):
    m = re.match(r'^\s*struct\s+(\w+)', line)
    if not m:
        continue
    structs += 1
    j = i - 1
    while j >= 0 and (lines[j].strip() == '' or lines[j].strip().startswith('//')):
        j -= 1
    annotations = lines[j].strip() if j >= 0 else ''
    if '@final' not in annotations:
        bad.append(f'{path}:{i + 1}: struct {m.group(1)} is not annotated @final (write "@final" on the line above)')
KEYED = {'ToolCommand': 'instrument', 'ForceFeedback': 'instrument', 'BodyState': 'organ'}
current = None
keys = {}
for i, line in enumerate(lines):
    m = re.match(r'^\s*struct\s+(\w+)', line)
    if m:
        current = m.group(1)
    code = line.split('//', 1)[0]
    if '@key' in code:
        k = re.search(r'@key\s+[\w\s]+?\s(\w+)\s*;', code)
        member = k.group(1) if k else '?'
        if KEYED.get(current) != member:
            bad.append(f'{path}:{i + 1}: @key {member} in struct {current}: only the instrument of ToolCommand and '
                       'ForceFeedback and the organ of BodyState are keys (a new key changes the wire format: make a '
                       'new module version)')
        keys[current] = member
for struct, member in KEYED.items():
    if keys.get(struct) != member:
        bad.append(f'{path}: struct {struct} must be keyed by `@key unsigned long {member};` (one instance per '
                   f'{member})')
# Every sequence and string is bounded: samples are preallocated, the loop never allocates.
for i, line in enumerate(lines):
    code = line.split('//', 1)[0]
    for m in re.finditer(r'\b(sequence|string)\s*(<[^>]*>)?', code):
        if m.group(1) == 'string' and m.group(2) is None and re.search(r'\bstring\s*<', code) is None:
            bad.append(f'{path}:{i + 1}: unbounded string: write string<N>')
        elif m.group(1) == 'sequence' and (m.group(2) is None or ',' not in m.group(2)):
            bad.append(f'{path}:{i + 1}: unbounded sequence: write sequence<T, N>')
# The frame of the web view: keyless (one stream), its JPEG a bounded octet sequence.
frame = re.search(r'struct\s+Frame\s*\{(.*?)\};', text, re.S)
if frame is None:
    bad.append(f'{path}: struct Frame (topic surgsim/frame: the JPEG stream of the web view) is missing')
elif not re.search(r'sequence\s*<\s*octet\s*,\s*\w+\s*>\s+jpeg\s*;', frame.group(1)):
    bad.append(f'{path}: struct Frame must carry its JPEG as `sequence<octet, kMaxFrameBytes> jpeg;` (bounded)')
if not re.search(r'module\s+v3\b', text):
    bad.append(f'{path}: the types must be in module surgsim::msg::v3 (the wire version keyed by instrument and '
               'by organ; a peer of another version never matches its topics)')
print('\n'.join(bad) if bad else f'check_idl_final: {structs} structs, all @final; keys: '
      + ', '.join(f'{s}.{m}' for s, m in sorted(KEYED.items())))
sys.exit(1 if bad or structs == 0 else 0)
