"""Compares the CSV files of two directories cell by cell: per file, whether they are
identical, else the largest relative difference and the largest difference relative to
the column's largest magnitude.  python3 bench/compare_csv.py DIR_A DIR_B"""
import csv,glob,os,sys
d1,d2=sys.argv[1],sys.argv[2]
for f in sorted(glob.glob(d1+'/*.csv')):
    g=os.path.join(d2,os.path.basename(f))
    a=list(csv.reader(open(f))); b=list(csv.reader(open(g)))
    cols=list(zip(*[[float(x) for x in r] for r in a[1:]]))
    scale=[max(abs(v) for v in c) for c in cols]
    worst=0; worst_s=0; same=True
    for ra,rb in zip(a[1:],b[1:]):
        for j,(x,y) in enumerate(zip(ra,rb)):
            if x!=y: same=False
            x=float(x);y=float(y)
            worst=max(worst,abs(x-y)/max(abs(x),1e-300))
            worst_s=max(worst_s,abs(x-y)/max(scale[j],1e-300))
    print(os.path.basename(f), 'identical' if same and len(a)==len(b) else f'max rel {worst:.2e}, rel to column max {worst_s:.2e}')
