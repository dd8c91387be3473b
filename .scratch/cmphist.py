import csv, sys, json
a=list(csv.DictReader(open(sys.argv[1]+'/history.csv'))); b=list(csv.DictReader(open(sys.argv[2]+'/history.csv')))
keys=['time','dt','newton_its','growth_mm','mu_bar','energy','negative_eigenvalues']
print(len(a),len(b))
worst=0
for i,(x,y) in enumerate(zip(a,b)):
    d=max(abs(float(x[k])-float(y[k]))/max(abs(float(x[k])),1e-12) for k in keys)
    worst=max(worst,d)
    if d>1e-6:
        print('first >1e-6 at row',i,d, [(x[k],y[k]) for k in ('time','newton_its','growth_mm')]); break
print('worst before', worst)
sa=json.load(open(sys.argv[1]+'/summary.json')); sb=json.load(open(sys.argv[2]+'/summary.json'))
for s in (sa,sb):
    pb=s.get('postbuckling',{})
    print(s['status'], s['steps'], [ (c['wrinkle_count'], round(c['growth_um'],4)) for c in pb.get('branch_crossings',[])], pb.get('contact') if 'contact' in pb else '')
