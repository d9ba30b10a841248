#!/usr/bin/python3
"""Every struct of idl/Surgsim.idl is annotated @final (the wire format is XCDR1, final, keyless: another vendor's
generator must not guess its extensibility), and none is keyed. Usage: check_idl_final.py IDL_FILE"""
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
for i, line in enumerate(lines):
    if '@key' in line.split('//', 1)[0]:
        bad.append(f'{path}:{i + 1}: @key: the surgsim types are keyless')
print('\n'.join(bad) if bad else f'check_idl_final: {structs} structs, all @final and keyless')
sys.exit(1 if bad or structs == 0 else 0)
