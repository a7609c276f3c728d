#!/usr/bin/env python3
"""Lists cycles among a crate's modules from its `use crate::` and `crate::` paths.

Usage: scripts/module-cycles.py CRATE_SRC [CRATE_SRC ...]

Modules are compared at depths 1 to 3 (`frames`, `frames::lobe`, ...); a module reaching into
its own parent or child is not an edge. Comments and the `#[cfg(test)]` module at a file's end
are left out: tests may reach anywhere. Exit status 1 where any cycle is found."""
import os, re, sys
from itertools import count

def modules(src):
    mods = {}
    for root, _, files in os.walk(src):
        for f in files:
            if not f.endswith('.rs'): continue
            p = os.path.join(root, f)
            rel = os.path.relpath(p, src)[:-3].split(os.sep)
            if rel[-1] in ('mod', 'lib', 'main'): rel = rel[:-1]
            mods['::'.join(rel)] = p
    return mods

def strip_comments(text):
    return '\n'.join(l for l in text.split('\n') if not l.lstrip().startswith('//'))

def strip_tests(text):
    # drop #[cfg(test)] mod tests { ... } blocks (to the end of file, as they are last)
    m = re.search(r'#\[cfg\(test\)\]\s*(pub(\(crate\))?\s+)?mod \w+\s*\{', text)
    return text[:m.start()] if m else text

def resolve(path, mods):
    parts = path.split('::')
    while parts:
        k = '::'.join(parts)
        if k in mods: return k
        parts = parts[:-1]
    return None

def main(src, depth):
    mods = modules(src)
    edges = {}
    for m, p in mods.items():
        text = strip_comments(strip_tests(open(p).read()))
        targets = set()
        for use in re.findall(r'use\s+crate::([^;]+);', text, re.S):
            use = re.sub(r'\s+', '', use)
            # expand one level of braces
            mm = re.match(r'([\w:]*?)::?\{(.*)\}$', use)
            items = [use] if not mm else [mm.group(1) + '::' + x for x in re.split(r',(?![^{]*\})', mm.group(2)) if x]
            for it in items:
                it = re.sub(r'\{.*', '', it).strip(':')
                targets.add(it)
        for path in re.findall(r'crate::((?:\w+::)*\w+)', text):
            targets.add(path)
        for t in targets:
            r = resolve(t, mods)
            if r is None: continue
            a = '::'.join(m.split('::')[:depth]); b = '::'.join(r.split('::')[:depth])
            if a and b and a != b and not b.startswith(a + '::') and not a.startswith(b + '::'):
                edges.setdefault(a, set()).add(b)
    # Tarjan SCC
    index = {}; low = {}; stack = []; on = set(); sccs = []; c = count()
    def strong(v):
        index[v] = low[v] = next(c); stack.append(v); on.add(v)
        for w in edges.get(v, ()):
            if w not in index: strong(w); low[v] = min(low[v], low[w])
            elif w in on: low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop(); on.discard(w); comp.append(w)
                if w == v: break
            if len(comp) > 1: sccs.append(sorted(comp))
    sys.setrecursionlimit(10000)
    for v in list(edges):
        if v not in index: strong(v)
    return sccs, edges

if __name__ == '__main__':
    bad = 0
    for src in sys.argv[1:]:
        for depth in (1, 2, 3):
            sccs, edges = main(src, depth)
            for s in sccs:
                bad += 1
                print(f'{src} (depth {depth}): cycle among', ', '.join(s))
                for a in s:
                    print('   ', a, '->', ', '.join(sorted(b for b in edges.get(a, ()) if b in s)))
    sys.exit(1 if bad else 0)
