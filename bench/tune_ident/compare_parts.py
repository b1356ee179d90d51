"""Two sets of varied.py outputs, part by part: the logs whose order, outcome or phase error changed, and the tallies.

Usage: python bench/tune_ident/compare_parts.py BEFORE_PREFIX AFTER_PREFIX PART [PART ...]
Reads ``{BEFORE_PREFIX}_{PART}.txt`` and ``{AFTER_PREFIX}_{PART}.txt`` (the same logs in the same order; e.g. parts
s1 s2 s1_10k w1 w2 of one session's runs). Prints each changed log (order, max dB, max deg over 0.1-15 Hz,
outcome; a changed phase error counts when it moved by more than 0.3 deg) and per run the four outcomes with the
summed identify seconds (s; runs not made side by side: no speed claim). compare_runs.py needs one file name per
run; this takes the parts as the session wrote them.
"""
import sys

KEYS=("WRONG_USABLE","RIGHT_REFUSED","WRONG_REFUSED")
def rows(p):
    """The log rows of one varied.py output: (id, max dB, max deg, order, outcome, seconds, conditions)."""
    out=[]
    for line in open(p):
        f=line.split()
        if len(f)<11 or f[0]=="design" or line.startswith("logs "): continue
        try: db,deg,s=float(f[3]),float(f[4]),float(f[9])
        except ValueError: continue
        kind=f[11] if len(f)>11 and f[11] in KEYS else "good"
        out.append((f"{f[0]} {f[1]} {f[2]}",db,deg,f[10],kind,s,line.split(" | ")[-1].strip()[:260]))
    return out


def main():
    """Compare the parts named on the command line (see the module)."""
    tot={}
    for part in sys.argv[3:]:
        a=rows(f"{sys.argv[1]}_{part}.txt"); b=rows(f"{sys.argv[2]}_{part}.txt")
        for tag,rs in (("before",a),("after",b)):
            for r in rs: tot.setdefault(tag,{}).setdefault(r[4],0); tot[tag][r[4]]+=1
            tot[tag]["secs"]=tot[tag].get("secs",0)+sum(r[5] for r in rs); tot[tag]["n"]=tot[tag].get("n",0)+len(rs)
        for x,y in zip(a,b):
            assert x[0]==y[0]
            if x[4]!=y[4] or x[3]!=y[3] or abs(x[2]-y[2])>0.3:
                print(f"{part} {x[0]}: {x[3]} {x[1]:.2f}dB {x[2]:.1f}deg {x[4]} -> {y[3]} {y[1]:.2f}dB {y[2]:.1f}deg {y[4]}  | {y[6] if y[4] in ('RIGHT_REFUSED',) else ''}")
    for t in tot: print(t, tot[t])


if __name__ == "__main__":
    main()
