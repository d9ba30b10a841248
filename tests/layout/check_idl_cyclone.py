#!/usr/bin/python3
"""Another vendor's generator reads idl/Surgsim.idl as Fast DDS's does: Cyclone DDS's `idlc` (Debian
cyclonedds-tools) compiles it to C, and the C compiles against Cyclone's headers (cyclonedds-dev). idlc runs with its
default extensibility set to appendable (-x appendable), so a struct whose @final it did not read would get a DHEADER
(DDS_OP_DLC) in its descriptor: there must be none. Each struct's descriptor lists its members in the IDL's order,
its type name is surgsim::msg::v3::NAME, and its keys are exactly ToolCommand.instrument, ForceFeedback.instrument and
BodyState.organ (every other struct keyless).
Usage: check_idl_cyclone.py IDL_FILE IDLC C_COMPILER"""
import os
import re
import subprocess
import sys
import tempfile

path, idlc, cc = sys.argv[1:4]
MODULE = 'surgsim_msg_v3'
KEYED = {'ToolCommand': ['instrument'], 'ForceFeedback': ['instrument'], 'BodyState': ['organ']}

if not (os.path.isfile(idlc) and os.access(idlc, os.X_OK)):
    print(f"Cyclone DDS's IDL compiler idlc not found ('{idlc}'): install the Debian package cyclonedds-tools "
          '(scripts/setup.sh installs it; by hand: apt-get install -y cyclonedds-tools cyclonedds-dev), then '
          're-run cmake')
    sys.exit(1)
if not os.path.isfile('/usr/include/dds/dds.h'):
    print("Cyclone DDS's headers not found (/usr/include/dds/dds.h): install the Debian package cyclonedds-dev "
          '(scripts/setup.sh installs it)')
    sys.exit(1)

# The structs of the IDL and their members, in order (comments dropped; one member per line).
text = re.sub(r'//[^\n]*', '', open(path, encoding='utf-8').read())
structs = {}
for m in re.finditer(r'\bstruct\s+(\w+)\s*\{(.*?)\};', text, re.S):
    members = []
    for decl in m.group(2).split(';'):
        decl = decl.strip()
        if decl:
            members.append(re.search(r'(\w+)\s*$', decl).group(1))
    structs[m.group(1)] = members

bad = []
with tempfile.TemporaryDirectory(prefix='surgsim-idlc-') as out:
    run = subprocess.run([idlc, '-x', 'appendable', '-l', 'c', '-o', out, path], capture_output=True, text=True)
    said = (run.stdout + run.stderr).strip()
    if run.returncode != 0 or said:
        print(f'{idlc} -x appendable -l c {path} (exit {run.returncode}):\n{said}')
        sys.exit(1)
    base = os.path.splitext(os.path.basename(path))[0]
    c_file = os.path.join(out, base + '.c')
    gen = open(c_file, encoding='utf-8').read()
    if re.search(r'DDS_OP_(DLC|PLC)', gen):
        bad.append(f'{c_file}: a descriptor has a DHEADER (DDS_OP_DLC/PLC): idlc took a struct as appendable or '
                   'mutable, so it did not read its @final')
    for name, members in structs.items():
        ops = re.search(r'static const uint32_t ' + MODULE + '_' + name + r'_ops \[\] =\s*\{\s*/\* ' + name +
                        r' \*/(.*?)DDS_OP_RTS', gen, re.S)
        if ops is None:
            bad.append(f'{c_file}: no descriptor ops for struct {name} ({MODULE}_{name}_ops)')
            continue
        got = re.findall(r'offsetof \(' + MODULE + '_' + name + r', (\w+)\)', ops.group(1))
        if got != members:
            bad.append(f'struct {name}: idlc gives the members {got}, the IDL declares {members} (same order '
                       'expected: XCDR1 final serializes them in declaration order)')
        desc = re.search(r'const dds_topic_descriptor_t ' + MODULE + '_' + name + r'_desc =\s*\{(.*?)\};', gen, re.S)
        if desc is None:
            bad.append(f'{c_file}: no topic descriptor for struct {name}')
            continue
        typename = re.search(r'\.m_typename = "([^"]*)"', desc.group(1)).group(1)
        if typename != f'surgsim::msg::v3::{name}':
            bad.append(f'struct {name}: idlc names it {typename}, expected surgsim::msg::v3::{name}')
        keys_block = re.search(r'dds_key_descriptor_t ' + MODULE + '_' + name + r'_keys\[\d+\] =\s*\{(.*?)\};', gen,
                               re.S)
        keys = re.findall(r'\{ "(\w+)"', keys_block.group(1)) if keys_block else []
        if keys != KEYED.get(name, []):
            bad.append(f'struct {name}: idlc reads the keys {keys}, expected {KEYED.get(name, [])}')
    # The generated C compiles against Cyclone's headers.
    compiled = subprocess.run([cc, '-std=c11', '-Wall', '-Werror', '-c', c_file, '-I', out, '-o',
                               os.path.join(out, base + '.o')], capture_output=True, text=True)
    if compiled.returncode != 0:
        bad.append(f'{cc} -c {c_file} (the C idlc generated) failed:\n{compiled.stderr}')
missing = sorted(set(KEYED) - set(structs))
if missing:
    bad.append(f'{path}: keyed structs missing: {missing}')
print('\n'.join(bad) if bad else f'check_idl_cyclone: idlc read {len(structs)} structs, all final, members in order; '
      'keys: ' + ', '.join(f'{s}.{k[0]}' for s, k in sorted(KEYED.items())) + '; the generated C compiles')
sys.exit(1 if bad or not structs else 0)
