#!/usr/bin/python3
"""Checks that common/ keeps its layering: every file in common/<folder>/ includes only its own folder and the
folders common/layers.txt allows for it, declares its code in namespace surgsim::<folder> (forward declarations of
an allowed folder's names aside), names no namespace surgsim::<other> of a folder it may not use (`other::x`,
`using namespace surgsim::other`), and nothing in common/ includes DDS or GL headers (those belong to the nodes). Usage: check_layout.py [ROOT] (default: the repository holding this script). Exit 0 when the layout holds,
1 with one line per violation (file:line, the include, what the folder may use, how to fix), 2 on a bad layers file."""
import os
import re
import sys

# Comments and string literals are blanked (same length, newlines kept) before the namespace rules are read.
CODE_NOISE = re.compile(r'//[^\n]*|/\*.*?\*/|"(?:\\.|[^"\\\n])*"|\'(?:\\.|[^\'\\\n])*\'', re.S)
NS_DECL = re.compile(r'\bnamespace\s+surgsim((?:::\w+)*)\s*\{')
NS_USE = re.compile(r'(?<![\w:])(?:surgsim::)?([a-z_]\w*)::')


def blank(text):
    return CODE_NOISE.sub(lambda m: re.sub(r'[^\n]', ' ', m.group()), text)


def namespace_problems(rel, text, folder, allowed, layers):
    """The namespace rules for one file of common/<folder>/: (line, message) pairs."""
    problems = []
    code = blank(text)
    line_of = lambda pos: code.count('\n', 0, pos) + 1
    for m in NS_DECL.finditer(code):
        parts = [p for p in m.group(1).split('::') if p]
        if not parts:
            problems.append((line_of(m.start()), f'declares namespace surgsim: the code of common/{folder}/ goes in '
                                                 f'namespace surgsim::{folder}'))
        elif parts[0] not in layers:
            problems.append((line_of(m.start()), f'declares namespace surgsim::{parts[0]}, which is no folder of '
                                                 f'common/: use surgsim::{folder}'))
        elif parts[0] not in allowed:
            problems.append((line_of(m.start()), f'declares namespace surgsim::{parts[0]}, but {folder}/ may not use '
                                                 f'{parts[0]}/ (common/layers.txt)'))
    for m in NS_USE.finditer(code):
        used = m.group(1)
        if used in layers and used not in allowed:
            may = 'only ' + ', '.join(sorted(layers[folder])) if layers[folder] else 'no other folder'
            problems.append((line_of(m.start()), f'names namespace {used}:: ({m.group().strip()}...), but {folder}/ '
                                                 f'may use {may} (common/layers.txt): move the code, or pass what it '
                                                 f'needs from {used}/ in as plain data'))
    for m in re.finditer(r'\busing\s+namespace\s+surgsim::(\w+)', code):
        used = m.group(1)
        if used in layers and used not in allowed and not NS_USE.match(code, m.start(1)):
            problems.append((line_of(m.start()), f'uses namespace surgsim::{used}, but {folder}/ may not use '
                                                 f'{used}/ (common/layers.txt)'))
    return problems

INCLUDE = re.compile(r'^\s*#\s*include\s*([<"])([^>"]+)[>"]')
# Headers that must never appear below the nodes: the model core has no DDS and no GL.
FORBIDDEN = (re.compile(r'^(fastdds|fastrtps|fastcdr)/'), re.compile(r'^(GL|osmesa)/'), re.compile(r'^Surgsim'),
             re.compile(r'^dds_support\.h$'))


def read_layers(path):
    layers = {}
    with open(path, encoding='utf-8') as f:
        for no, raw in enumerate(f, 1):
            line = raw.split('#', 1)[0].strip()
            if not line:
                continue
            m = re.match(r'^([a-z_]+):\s*(.*)$', line)
            if not m:
                print(f'{path}:{no}: not "folder: allowed folders ..."', file=sys.stderr)
                sys.exit(2)
            layers[m.group(1)] = set(m.group(2).split())
    for name, deps in layers.items():
        for d in deps:
            if d not in layers:
                print(f'{path}: {name} may use "{d}", which is not a folder of the table', file=sys.stderr)
                sys.exit(2)
    return layers


def main():
    root = os.path.abspath(sys.argv[1] if len(sys.argv) > 1 else os.path.join(os.path.dirname(__file__), '..'))
    common = os.path.join(root, 'common')
    layers_file = os.path.join(common, 'layers.txt')
    layers = read_layers(layers_file)
    problems = []
    checked = 0
    for folder in sorted(os.listdir(common)):
        path = os.path.join(common, folder)
        if not os.path.isdir(path):
            continue
        if folder not in layers:
            problems.append(f'common/{folder}/: a folder that common/layers.txt does not list (add its line: what it '
                            f'may include)')
            continue
        allowed = layers[folder] | {folder}
        for dirpath, _, files in os.walk(path):
            for name in sorted(files):
                if not name.endswith(('.h', '.hpp', '.cpp', '.cc')):
                    continue
                file = os.path.join(dirpath, name)
                rel = os.path.relpath(file, root)
                checked += 1
                with open(file, encoding='utf-8', errors='replace') as f:
                    whole = f.read()
                for no, message in namespace_problems(rel, whole, folder, allowed, layers):
                    problems.append(f'{rel}:{no}: {message}')
                if True:
                    for no, text in enumerate(whole.splitlines(), 1):
                        m = INCLUDE.match(text)
                        if not m:
                            continue
                        kind, target = m.groups()
                        if any(p.search(target) for p in FORBIDDEN):
                            problems.append(f'{rel}:{no}: includes {kind}{target}{">" if kind == "<" else kind}: common/ has no DDS or GL '
                                            f'(move this code to haptic_node/ or visual_node/)')
                            continue
                        if kind != '"':
                            continue
                        if '/' not in target:
                            if os.path.exists(os.path.join(dirpath, target)):
                                continue  # a private header of the same folder
                            problems.append(f'{rel}:{no}: includes "{target}" without its folder (write '
                                            f'"<folder>/{target}", e.g. "{folder}/{target}")')
                            continue
                        used = target.split('/', 1)[0]
                        if used not in layers:
                            problems.append(f'{rel}:{no}: includes "{target}": "{used}" is not a folder of common/')
                        elif used not in allowed:
                            may = 'only ' + ', '.join(sorted(layers[folder])) if layers[folder] else 'no other folder'
                            problems.append(f'{rel}:{no}: includes "{target}", but {folder}/ may use {may} '
                                            f'(common/layers.txt): move the code, or pass what it needs from '
                                            f'{used}/ in as plain data')
    for p in problems:
        print(p)
    if problems:
        print(f'check_layout: {len(problems)} violation(s) in {checked} files under {common}')
        return 1
    print(f'check_layout: {checked} files in {len(layers)} subsystems keep to common/layers.txt')
    return 0


if __name__ == '__main__':
    sys.exit(main())
