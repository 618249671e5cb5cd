#!/usr/bin/env python3
"""Functions longer than a bound, longest first (issue 15's bounds: 120 lines
in refloc, 150 in mapc).

    scripts/fn-lengths.py 120 crates/refloc/src
    scripts/fn-lengths.py 150 crates/mapc/src

Counts from the `fn` line to its closing brace, after blanking comments,
strings and char literals so that braces inside them do not count. A text
scan, not a parser: good enough for rustfmt-formatted code.
"""
import re,sys,os
def strip(src):
    # blank out comments, strings, char literals, keeping newlines
    out=[];i=0;n=len(src)
    while i<n:
        c=src[i]
        if src.startswith('//',i):
            j=src.find('\n',i); j=n if j<0 else j; out.append(' '*(j-i)); i=j; continue
        if src.startswith('/*',i):
            j=src.find('*/',i+2); j=n if j<0 else j+2; out.append(re.sub(r'[^\n]',' ',src[i:j])); i=j; continue
        m=re.match(r'b?r(#*)"',src[i:i+10])
        if m and (i==0 or not (src[i-1].isalnum() or src[i-1]=='_')):
            hashes=m.group(1); end='"'+hashes; j=src.find(end,i+m.end()); j=n if j<0 else j+len(end)
            out.append(re.sub(r'[^\n]',' ',src[i:j])); i=j; continue
        if c=='"' :
            j=i+1
            while j<n and src[j]!='"':
                j+= 2 if src[j]=='\\' else 1
            j+=1; out.append(re.sub(r'[^\n]',' ',src[i:j])); i=j; continue
        if c=="'":
            m=re.match(r"'(\\.[^']*|[^\\'])'",src[i:i+12])
            if m: out.append(' '*m.end()); i+=m.end(); continue
        out.append(c); i+=1
    return ''.join(out)
def scan(path):
    src=strip(open(path).read())
    out=[]
    for m in re.finditer(r'^[ \t]*(?:pub(?:\([^)]*\))? )?(?:const )?(?:unsafe )?(?:extern "C" )?fn ([A-Za-z0-9_]+)', src, re.M):
        i=src.find('{', m.end()); semi=src.find(';', m.end())
        if i<0 or (0<=semi<i): continue
        depth=0;j=i
        while j<len(src):
            if src[j]=='{':depth+=1
            elif src[j]=='}':
                depth-=1
                if depth==0:break
            j+=1
        l0=src.count('\n',0,m.start())+1; l1=src.count('\n',0,j)+1
        out.append((l1-l0+1,path,l0,m.group(1)))
    return out
res=[]
for root in sys.argv[2:]:
    for d,_,fs in os.walk(root):
        for f in fs:
            if f.endswith('.rs'): res+=scan(os.path.join(d,f))
lim=int(sys.argv[1])
try:
    for r in sorted(res,reverse=True):
        if r[0]>lim: print(*r)
except BrokenPipeError:
    pass
