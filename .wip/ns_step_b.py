# Step B: qualify other folders' names in headers; using-directives in .cpp files; surgsim::X -> surgsim::g::X.
import json, os, re, subprocess, sys, collections
root='/work/main'; os.chdir(root)
FOLDERS=['core','concurrency','os','mesh','tool','fem','compliance','nonlinear','contact','liver','intestine','scene','mesher','imaging','apps']
tags=[json.loads(l) for l in subprocess.check_output(['ctags','-R','--output-format=json','--fields=+SZKsnp','--c++-kinds=+p','common'],text=True).splitlines() if l.startswith('{')]
sym=collections.defaultdict(set)   # name -> {(folder, kind)}
unscoped_enums=set()
for t in tags:
    if t.get('kind')=='enum' and 'enum class' not in t.get('pattern','') and 'enum struct' not in t.get('pattern',''):
        unscoped_enums.add((t['path'], t['name']))
for t in tags:
    path=t['path']
    if not path.endswith('.h') or path.startswith('common/apps'): continue
    folder=path.split('/')[1]
    scope=t.get('scope',''); kind=t['kind']; name=t['name']
    if name.startswith('__anon') or name.startswith('operator'): continue
    ns=f'surgsim::{folder}'
    if scope==ns and kind in ('class','struct','enum','typedef','function','prototype','variable','namespace','alias','union'):
        k='type' if kind in ('class','struct','enum','typedef','alias','union','namespace') else ('func' if kind in ('function','prototype') else 'var')
        sym[name].add((folder,k))
    elif kind=='enumerator' and t.get('scopeKind')=='enum':
        enum=scope.split('::')[-1]; parent='::'.join(scope.split('::')[:-1])
        if parent==ns and (path,enum) in unscoped_enums: sym[name].add((folder,'var'))
# templates declared with template<> lines: ctags gives them as class/function - fine
amb={n:v for n,v in sym.items() if len({f for f,_ in v})>1}
if '--dump' in sys.argv:
    for n in sorted(sym): print(n, sorted(sym[n]))
    print('AMBIGUOUS', amb); sys.exit()
uniq={n:(next(iter(v))[0], {k for _,k in v}) for n,v in sym.items() if n not in amb}

TOKEN=re.compile(r'''(?P<ws>\s+)|(?P<lc>//[^\n]*)|(?P<bc>/\*.*?\*/)|(?P<raw>R"(?P<d>[^(]*)\(.*?\)(?P=d)")|(?P<str>"(?:\\.|[^"\\\n])*")|(?P<chr>'(?:\\.|[^'\\\n])*')|(?P<pp>^[ \t]*#[^\n]*(?:\\\n[^\n]*)*)|(?P<id>[A-Za-z_]\w*)|(?P<num>\d[\w.']*)|(?P<op>::|->|&&|\|\||==|!=|<=|>=|\+=|-=|\*=|/=|.)''', re.S|re.M)
KEYWORDS_PREV={'return','throw','else','case','do','sizeof','new','delete','co_return','const','constexpr','static','inline','typename','virtual','explicit','friend','mutable','volatile','extern','using','template','noexcept','decltype','alignof','static_assert','if','while','for','switch','operator','auto','public','private','protected','final','override'}
CALL_PREV={'(',',','=','{',';','?',':','!','+','-','/','[','&&','||','==','!=','+=','-=','*=','/=','}','<','>','<=','>=','return','throw','else','case','do','%','|','^','~'}

def toks(s):
    out=[]
    for m in TOKEN.finditer(s):
        g=m.lastgroup
        if g in ('ws',): continue
        out.append((g,m.start(),m.end(),m.group()))
    return out

def own_names(path):
    names=set()
    try:
        for l in subprocess.check_output(['ctags','--output-format=json','--fields=+Ks','--c++-kinds=+plzx','-o','-',path],text=True).splitlines():
            if not l.startswith('{'): continue
            t=json.loads(l)
            if t.get('scopeKind') in ('class','struct','function','union') or t['kind'] in ('local','parameter','member'): names.add(t['name'])
    except subprocess.CalledProcessError: pass
    return names

def folder_of(path):
    p=path.split('/')
    return p[1] if p[0]=='common' and len(p)>2 else None

def qualify(path, s, own):
    T=toks(s); edits=[]; skipn=own_names(path)
    sig=[t for t in T if t[0] in ('id','op','num','str','chr','raw')]
    for i,(g,a,b,text) in enumerate(sig):
        if g!='id' or text not in uniq: continue
        f,kinds=uniq[text]
        if f==own or text in skipn: continue
        prev=sig[i-1][3] if i>0 else ''
        nxt=sig[i+1][3] if i+1<len(sig) else ''
        if prev in ('::','.','->','~','class','struct','enum','namespace','union','#','goto'): continue
        if 'type' in kinds:
            pass
        elif 'func' in kinds:
            if nxt not in ('(','<') : 
                if nxt in (')',',') and prev in ('(',',','&','='): pass  # function passed as a value
                else: continue
            if prev not in CALL_PREV: continue
        else:  # var
            if sig[i-1][0]=='id' and prev not in KEYWORDS_PREV: continue
            if prev=='>' : continue
        edits.append((a, f+'::'))
    for a,ins in sorted(edits, reverse=True): s=s[:a]+ins+s[a:]
    return s, len(edits)

def used_folders(path, s, own):
    T=toks(s); used=set()
    sig=[t for t in T if t[0] in ('id','op')]
    for i,(g,a,b,text) in enumerate(sig):
        if g!='id': continue
        prev=sig[i-1][3] if i>0 else ''
        if prev in ('.','->'): continue
        if prev=='::' and not (i>1 and sig[i-2][3]=='surgsim'): continue
        if text in sym:
            for f,_ in sym[text]:
                if f!=own: used.add(f)
        if text in FOLDERS and i+1<len(sig) and sig[i+1][3]=='::' and prev!='::': pass
    return used

files=[f for f in subprocess.check_output(['git','ls-files'],text=True).split() if f.endswith(('.h','.cpp')) and f.split('/')[0] in ('common','haptic_node','visual_node','tests')]
files+= [f for f in subprocess.check_output(['git','ls-files','--others','--exclude-standard'],text=True).split() if f.endswith(('.h','.cpp'))]
total=0
for f in files:
    s=open(f).read(); o=s; own=folder_of(f)
    # surgsim::Name -> surgsim::folder::Name (anywhere, comments included)
    def rep(m):
        n=m.group(1)
        if n in uniq: return f'surgsim::{uniq[n][0]}::{n}'
        return m.group(0)
    s=re.sub(r'\bsurgsim::([A-Za-z_]\w*)\b(?!::\w+\s*\{)', rep, s)
    if f.endswith('.h'):
        s,n=qualify(f,s,own); total+=n
    else:
        used=used_folders(f,s,own)
        if own in ('apps',): used=used  # apps: same
        used=[u for u in FOLDERS if u in used]
        if used:
            lines=s.split('\n'); last=-1
            for i,l in enumerate(lines):
                if re.match(r'\s*#\s*include',l): last=i
            block=['']+[f'using namespace surgsim::{u};' for u in used]
            lines[last+1:last+1]=block
            s='\n'.join(lines)
    if s!=o: open(f,'w').write(s)
print('qualified', total)
