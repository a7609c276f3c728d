#!/usr/bin/env python3
"""Counts a library crate's public items from rustdoc's JSON (needs a nightly toolchain).

Usage: scripts/public-items.py CRATE [--list]

Walks the crate's public paths from its root, following re-exports, and counts each distinct
named item once: modules, functions, structs, enums, traits, constants, statics, type aliases
and macros. Enum variants, fields and methods are counted apart (methods: the public inherent
methods of the counted types). --list prints every counted item's path.
The JSON is built in target/public-items (cargo +nightly rustdoc ... --output-format json, or the
stable toolchain with RUSTC_BOOTSTRAP=1 where no nightly is installed)."""
import json, os, subprocess, sys

NAMED = {'module', 'function', 'struct', 'enum', 'trait', 'constant', 'static', 'type_alias',
         'macro', 'union', 'trait_alias'}

def build(crate):
    target = os.path.join('target', 'public-items')
    args = ['rustdoc', '-q', '-p', crate, '--lib', '--locked', '--', '-Z', 'unstable-options',
            '--output-format', 'json']
    env = {**os.environ, 'CARGO_TARGET_DIR': target}
    # A nightly toolchain where there is one; else the stable one with its unstable options
    # unlocked (RUSTC_BOOTSTRAP), as on machines that can fetch no other toolchain.
    if subprocess.run(['cargo', '+nightly'] + args, env=env,
                      stderr=subprocess.DEVNULL).returncode != 0:
        subprocess.run(['cargo'] + args, check=True, env={**env, 'RUSTC_BOOTSTRAP': '1'})
    return os.path.join(target, 'doc', crate.replace('-', '_') + '.json')

def kind(item):
    return next(iter(item['inner']))

def main():
    crate = sys.argv[1]
    with open(build(crate)) as f:
        doc = json.load(f)
    index = doc['index']
    seen, paths, methods = set(), [], 0

    def visit(iid, path):
        nonlocal methods
        item = index.get(str(iid))
        if item is None or item['crate_id'] != 0:
            return
        k = kind(item)
        if k == 'use':
            use = item['inner']['use']
            if use['id'] is None:
                return
            target = index.get(str(use['id']))
            if use['is_glob'] and target is not None and kind(target) == 'module':
                for child in target['inner']['module']['items']:
                    visit(child, path)
            else:
                visit(use['id'], path + [use['name']])
            return
        if k not in NAMED or iid in seen:
            return
        seen.add(iid)
        paths.append((k, '::'.join(path)))
        if k == 'module':
            for child in item['inner']['module']['items']:
                child_item = index.get(str(child))
                if child_item is None:
                    continue
                # A re-export names itself (visit adds its name); other items by their own.
                visit(child, path if kind(child_item) == 'use' else path + [child_item['name']])
        if k in ('struct', 'enum'):
            for imp in item['inner'][k]['impls']:
                imp_item = index.get(str(imp))
                if imp_item is None or imp_item['inner']['impl']['trait'] is not None:
                    continue
                for m in imp_item['inner']['impl']['items']:
                    mi = index.get(str(m))
                    if mi is not None and mi['visibility'] == 'public':
                        methods += 1

    visit(doc['root'], [crate.replace('-', '_')])
    counts = {}
    for k, _ in paths:
        counts[k] = counts.get(k, 0) + 1
    if '--list' in sys.argv:
        for k, p in sorted(paths, key=lambda x: x[1]):
            print(f'{k:10} {p}')
    detail = ', '.join(f'{k} {n}' for k, n in sorted(counts.items()))
    print(f'{crate}: {len(paths)} public items ({detail}); {methods} public inherent methods')

if __name__ == '__main__':
    main()
