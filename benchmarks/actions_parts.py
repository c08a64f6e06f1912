"""The shipped right-shin model on everyday motion it never saw (issue 41): the action clips of
both Bandai-Namco sets, a virtual phone at the right ankle, `phone` noise, test seed 1000, scored
per body-part group (legs, arms, trunk) against the mean pose of 120 bandai-namco-2 clips.

    python benchmarks/actions_parts.py      # needs ../shared/data and the [deep] extra
"""
from pathlib import Path

from imuloco.app.pipeline import shipped_model
from imuloco.io.database import load_database, load_databases
from imuloco.lab.bench import aggregate, measure
from imuloco.methods import get_method, load_model
from imuloco.methods.training import synthesize

D = Path(__file__).resolve().parents[1].parent / 'shared' / 'data'
acts=load_databases([D/'bandai-namco-1-actions', D/'bandai-namco-2-actions'], progress=False)
train=load_database(D/'bandai-namco-2', limit=120, progress=False)
ex=synthesize(acts,['right_ankle'],'phone',1000)
mean=get_method('mean').fit(train,['right_ankle'],'phone',0)
model=load_model(shipped_model('learned','right_ankle'))
for name,m in (('mean',mean),('shipped',model)):
    clips=measure(m,ex)['clips']
    contents=sorted({c['motion_type'] for c in clips})
    a=aggregate(clips)
    print(name,'ALL', {k: round(a[k],2) for k in ('mpjpe_cm','legs_cm','arms_cm','trunk_cm','foot_skate_cm_s','foot_skate_gt_cm_s')})
    for c in contents:
        a=aggregate([r for r in clips if r['motion_type']==c])
        print(' ',name,c, {k: round(a[k],2) for k in ('mpjpe_cm','legs_cm','arms_cm','trunk_cm')})
