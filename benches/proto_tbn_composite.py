"""Prototype (issue 4): a graph-cut compositing pass after texture-by-numbers.

    PYTHONPATH=python python benches/proto_tbn_composite.py [ROUNDS] [NCAND]

Takes the medoid output's sources, and over overlapping windows (32², stride 16, random
phase per round) tries an alpha-expansion of each of the window's most frequent offsets
(Kwatra et al. 2003's seam cost |A(p)-B(p)| + |A(q)-B(q)| between two offsets' copies, zero
where they agree; an offset may only take pixels whose copy has the output's label). Every
output pixel stays a copy of an exemplar pixel of its label. Prints coherence / histogram /
Laplacian-variance ratios (to the thesis' bi, bi, the photo) before and after.
"""
import sys, time, numpy as np, cv2, phloem
from pathlib import Path
from phloem.metrics import patch_coherence, label_histogram_distance
RUNS = Path(__file__).resolve().parents[2] / "shared" / "data" / "bark" / "thesis_runs"
NAMES = ["bark1","bark2","eucalyptus","eucap5"]
def labels(p):
    g = phloem.io.read_image(p); g = g[..., :3].mean(axis=2) if g.ndim == 3 else g
    return np.round(g*255).astype(np.int32)
def load(name):
    d = RUNS/name
    ai = phloem.io.read_image(next(d.glob("ai.*")))[..., :3]
    return ai, labels(d/"a.png"), labels(d/"b.png"), phloem.io.read_image(d/"bi.png")[..., :3]
def lap(img): return cv2.Laplacian(np.ascontiguousarray(img.mean(axis=2)).astype(np.float32), cv2.CV_32F).var()
_cache = {}
def base(name, sel="medoid"):
    k=(name,sel)
    if k not in _cache:
        ai,a,b,bi = load(name)
        out, src = phloem.texture.by_numbers(ai,a,b,seed=0,selection=sel,return_sources=True)
        _cache[k]=(ai,a,b,bi,out,src)
    return _cache[k]
_bi={}
def score(name, out):
    ai,a,b,bi = load(name)
    if name not in _bi: _bi[name]=(patch_coherence(bi,ai), label_histogram_distance(bi,b,ai,a))
    cb,hb=_bi[name]
    return patch_coherence(out,ai)/cb, label_histogram_distance(out,b,ai,a)/hb, lap(out)/lap(ai)
from phloem.seams import grid_maxflow
INF=np.inf
def expand(ai, a, b, src, S=32, stride=16, rounds=2, ncand=3, seed=0, norm=2, verbose=False):
    h,w=b.shape; eh,ew=a.shape
    Y,X=np.mgrid[0:h,0:w]
    off=np.stack([src[...,0]-Y, src[...,1]-X],-1).astype(np.int64)
    rng=np.random.default_rng(seed)
    def copies(o, ys, xs):  # colour & valid of offset o (2,) or (...,2) at pixel grids
        sy=ys+o[...,0]; sx=xs+o[...,1]
        ok=(sy>=0)&(sy<eh)&(sx>=0)&(sx<ew)
        cy=np.clip(sy,0,eh-1); cx=np.clip(sx,0,ew-1)
        ok&=a[cy,cx]==b[ys,xs]
        return ai[cy,cx], ok
    def nrm(d): return np.sqrt((d*d).sum(-1)) if norm==2 else np.abs(d).sum(-1)
    total=0
    for rd in range(rounds):
        oy,ox=rng.integers(0,stride,2)
        wins=[(y0,x0) for y0 in range(-oy,h,stride) for x0 in range(-ox,w,stride)]
        rng.shuffle(wins)
        for y0,x0 in wins:
            y1,x1=max(0,y0),max(0,x0); y2,x2=min(h,y0+S),min(w,x0+S)
            if y2-y1<2 or x2-x1<2: continue
            # extended by 1 for border pairs
            ey1,ex1,ey2,ex2=max(0,y1-1),max(0,x1-1),min(h,y2+1),min(w,x2+1)
            ys,xs=Y[ey1:ey2,ex1:ex2],X[ey1:ey2,ex1:ex2]
            cur=off[ey1:ey2,ex1:ex2]
            inner=np.zeros(ys.shape,bool); inner[y1-ey1:y2-ey1,x1-ex1:x2-ex1]=True
            u,cnt=np.unique(cur[inner].reshape(-1,2),axis=0,return_counts=True)
            cands=u[np.argsort(-cnt)[:ncand]]
            cc,_=copies(cur,ys,xs)
            for al in cands:
                cur=off[ey1:ey2,ex1:ex2]
                cc,_=copies(cur,ys,xs)
                ac,aok=copies(al,ys,xs)
                same=np.all(cur==al,-1)
                nd=nrm(cc-ac)  # |I(p+cur_p) - I(p+al)|
                H,W=ys.shape
                src_c=np.zeros((H,W)); snk_c=np.zeros((H,W))
                edges=np.zeros((H,W,4))
                # pairs east and south
                for k,(dy,dx) in enumerate([(0,1),(1,0)]):
                    P=(slice(0,H-dy),slice(0,W-dx)); Q=(slice(dy,H),slice(dx,W))
                    cp=cur[P]; cq=cur[Q]
                    # V(o1,o2) at pair = |I(p+o1)-I(p+o2)| + |I(q+o1)-I(q+o2)|
                    ip_cq,_=copies(cq,ys[P],xs[P]); iq_cp,_=copies(cp,ys[Q],xs[Q])
                    A=nrm(cc[P]-ip_cq)+nrm(iq_cp-cc[Q])
                    ip_al=ac[P]; iq_al=ac[Q]
                    Bv=nd[P]+nrm(iq_al-cc[Q])*1 if False else None
                    # B: p cur, q al: |I(p+cp)-I(p+al)| + |I(q+cp)-I(q+al)|
                    B=nd[P]+nrm(iq_cp-iq_al)
                    # C: p al, q cur: |I(p+al)-I(p+cq)| + |I(q+al)-I(q+cq)|
                    C=nrm(ip_al-ip_cq)+nd[Q]
                    inP=inner[P]; inQ=inner[Q]
                    both=inP&inQ
                    # unary for p: (C-A) on x_p; for q: (D-C)=-C on x_q; pair (B+C-A)(1-xp)xq
                    def addu(sl, mask, c):
                        s=src_c[sl]; t=snk_c[sl]
                        s+=np.where(mask&(c>0),c,0); t+=np.where(mask&(c<0),-c,0)
                    addu(P, both, C-A); addu(Q, both, -C)
                    pe=np.maximum(B+C-A,0)*both
                    edges[P][...,k]+=pe  # from p to its E (k=0) or S (k=1) neighbour
                    # border pairs: p inner, q outer fixed 0: E(xp,0) = A or C  -> (C-A) on xp
                    addu(P, inP&~inQ, C-A)
                    # p outer fixed 0, q inner: E(0,xq) = A or B -> (B-A) on xq
                    addu(Q, inQ&~inP, B-A)
                src_c[~aok|~inner]=INF
                flow,sink=grid_maxflow(src_c,snk_c,edges,directed=True)
                take=sink&inner&aok
                if take.any() and not np.all(same[take]):
                    o=off[ey1:ey2,ex1:ex2]; o[take]=al; total+=int(take.sum())
        if verbose: print('round',rd,total,flush=True)
    return np.stack([Y+off[...,0],X+off[...,1]],-1)


if __name__ == "__main__":
    import time
    rounds = int(sys.argv[1]) if len(sys.argv) > 1 else 3
    ncand = int(sys.argv[2]) if len(sys.argv) > 2 else 6
    for n in NAMES:
        ai, a, b, bi, out, src = base(n)
        t = time.time()
        s2 = expand(ai, a, b, src, rounds=rounds, ncand=ncand)
        o2 = ai[s2[..., 0], s2[..., 1]]
        assert (a[s2[..., 0], s2[..., 1]] == b).all()
        print(n, "medoid", ["%.3f" % v for v in score(n, out)], "composited", ["%.3f" % v for v in score(n, o2)], "%.1fs" % (time.time() - t), flush=True)
