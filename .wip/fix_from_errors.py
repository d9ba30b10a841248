# Inserts the namespace the compiler suggests ("'X' was not declared...; did you mean 'surgsim::g::X'?").
import re, sys, collections
pat=re.compile(r"^(/work/wip/[^:]+):(\d+):(\d+): error: ‘(\w+)’ (?:was not declared in this scope|does not name a type|has not been declared|is not a (?:type|template)|was not declared)[^;]*; did you mean ‘surgsim::((?:\w+::)+)(\w+)’\?")
fix=collections.defaultdict(set)
for l in open(sys.argv[1]):
    m=pat.match(l)
    if not m: continue
    f,line,col,name,ns,name2=m.groups()
    if name!=name2: continue
    fix[f].add((int(line),int(col),name,ns))
n=0
for f,items in fix.items():
    lines=open(f).read().split('\n')
    for line,col,name,ns in sorted(items,reverse=True):
        L=lines[line-1]; c=col-1
        if L[c:c+len(name)]!=name: continue
        if c>=2 and L[c-2:c]=='::': continue
        lines[line-1]=L[:c]+ns+L[c:]; n+=1
    open(f,'w').write('\n'.join(lines))
print('fixed',n,'in',len(fix),'files')
# using-directives of namespaces the translation unit never declares: drop the line.
bad=re.compile(r"^(/work/wip/[^:]+):(\d+):\d+: error: ‘(\w+)’ is not a namespace-name")
drop=collections.defaultdict(set)
for l in open(sys.argv[1]):
    m=bad.match(l)
    if m: drop[m.group(1)].add((int(m.group(2)), m.group(3)))
for f,ls in drop.items():
    lines=open(f).read().split('\n')
    for i,ns in sorted(ls,reverse=True):
        if lines[i-1].strip()==f'using namespace surgsim::{ns};': del lines[i-1]  # idempotent: checks the name
    open(f,'w').write('\n'.join(lines))
print('dropped directives in',len(drop),'files')
