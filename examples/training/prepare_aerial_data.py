#!/usr/bin/env python3
"""Stage openly licensed aerial / drone detection data for the AeroDaaS aerial detector (how the training and
evaluation sets of aerodaas/perception/models/DATA_CARD.md were made; then run `aerodaas train detector` on them).

Classes (our ids): 0 car, 1 large_vehicle (truck/bus/van/other vehicle), 2 person.

Reads bare git mirrors under $AERIAL_MIRRORS (no work tree needed: uses `git cat-file --batch`),
copies the image bytes unchanged (no re-encode) and writes, per source,
    $AERIAL_DATA_OUT/<source>/images/<name>.(jpg|png)
    $AERIAL_DATA_OUT/<source>/labels/<name>.txt        (YOLO: cls cx cy w h, normalised)
    $AERIAL_DATA_OUT/<source>/cards_part.csv
and then rebuilds $AERIAL_DATA_OUT/cards.csv as the concatenation of all cards_part.csv.

Usage:  python3 prepare.py                 # stage all known sources
        python3 prepare.py jekhor hit_uav  # stage only these (cards.csv still merges all parts)
Only numpy / opencv / stdlib (opencv only used to read sizes of images that need it).
"""
import csv
import json
import os
import subprocess
import sys
from collections import Counter, defaultdict

# where the staged sets go (a cache folder, never the repository) and where the public repositories are cloned
# (bare mirrors named owner+repo/repo: git clone --mirror https://github.com/jekhor/aerial-cars-dataset
# jekhor+aerial-cars-dataset/repo, and likewise suojiashun/HIT-UAV-Infrared-Thermal-Dataset)
OUT = os.environ.get('AERIAL_DATA_OUT', os.path.expanduser('~/.cache/aerodaas/aerial'))
MIRROR = os.environ.get('AERIAL_MIRRORS', os.path.expanduser('~/.cache/aerodaas/mirrors'))
COLS = ['image', 'source', 'group', 'split', 'licence', 'licence_url', 'attribution', 'view',
        'altitude_m', 'modality', 'n_car', 'n_large_vehicle', 'n_person',
        'angle_deg', 'orig_name', 'notes']

LIC = {
    'CC-BY-3.0': 'https://creativecommons.org/licenses/by/3.0/',
    'CC-BY-4.0': 'https://creativecommons.org/licenses/by/4.0/',
    'CC-BY-SA-4.0': 'https://creativecommons.org/licenses/by-sa/4.0/',
    'CC0-1.0': 'https://creativecommons.org/publicdomain/zero/1.0/',
    'MIT': 'https://opensource.org/licenses/MIT',
    'Apache-2.0': 'https://www.apache.org/licenses/LICENSE-2.0',
}


# --------------------------------------------------------------------------- helpers
class GitReader:
    """Read many blobs from one bare repo through a single `git cat-file --batch` process."""

    def __init__(self, gitdir):
        self.gitdir = gitdir
        self.p = subprocess.Popen(['git', '-C', gitdir, 'cat-file', '--batch'],
                                  stdin=subprocess.PIPE, stdout=subprocess.PIPE)

    def ls(self, rev='HEAD', path=''):
        args = ['git', '-C', self.gitdir, 'ls-tree', '-r', '--name-only', rev]
        if path:
            args.append(path)
        return subprocess.run(args, capture_output=True, text=True, check=True).stdout.split('\n')[:-1]

    def read(self, path, rev='HEAD'):
        """bytes of rev:path, or None if the blob is absent (e.g. >= 4 MiB files not mirrored)."""
        self.p.stdin.write(f'{rev}:{path}\n'.encode())
        self.p.stdin.flush()
        header = self.p.stdout.readline().decode().split()
        if len(header) < 3 or header[1] != 'blob':
            return None
        n = int(header[2])
        data = self.p.stdout.read(n)
        self.p.stdout.read(1)  # trailing LF
        return data

    def close(self):
        self.p.stdin.close()
        self.p.wait()


def img_size(data):
    """(w, h) from PNG/JPEG header without decoding; fall back to cv2."""
    if data[:8] == b'\x89PNG\r\n\x1a\n':
        return int.from_bytes(data[16:20], 'big'), int.from_bytes(data[20:24], 'big')
    i = 2
    while i < len(data) - 9:
        if data[i] != 0xFF:
            i += 1
            continue
        m = data[i + 1]
        if m in (0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC9, 0xCA, 0xCB, 0xCD, 0xCE, 0xCF):
            return int.from_bytes(data[i + 7:i + 9], 'big'), int.from_bytes(data[i + 5:i + 7], 'big')
        if m in (0xD8, 0x01) or 0xD0 <= m <= 0xD7:
            i += 2
            continue
        i += 2 + int.from_bytes(data[i + 2:i + 4], 'big')
    import cv2
    import numpy as np
    im = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    return im.shape[1], im.shape[0]


def clip_yolo(cls, cx, cy, w, h):
    x0, y0, x1, y1 = max(0., cx - w / 2), max(0., cy - h / 2), min(1., cx + w / 2), min(1., cy + h / 2)
    if x1 - x0 <= 1e-4 or y1 - y0 <= 1e-4:
        return None
    return (cls, (x0 + x1) / 2, (y0 + y1) / 2, x1 - x0, y1 - y0)


class Stager:
    def __init__(self, source):
        self.source = source
        self.root = os.path.join(OUT, source)
        os.makedirs(os.path.join(self.root, 'images'), exist_ok=True)
        os.makedirs(os.path.join(self.root, 'labels'), exist_ok=True)
        self.rows = []

    def add(self, name, data, boxes, **card):
        """name: output stem + ext; boxes: list of (cls,cx,cy,w,h) normalised."""
        stem, ext = os.path.splitext(name)
        ext = ext.lower().replace('jpeg', 'jpg')
        ip = os.path.join(self.root, 'images', stem + ext)
        if not (os.path.exists(ip) and os.path.getsize(ip) == len(data)):
            with open(ip, 'wb') as f:
                f.write(data)
        boxes = [b for b in (clip_yolo(*b) for b in boxes) if b]
        with open(os.path.join(self.root, 'labels', stem + '.txt'), 'w') as f:
            for c, cx, cy, w, h in boxes:
                f.write(f'{c} {cx:.6f} {cy:.6f} {w:.6f} {h:.6f}\n')
        cnt = Counter(b[0] for b in boxes)
        row = dict(image=os.path.relpath(ip, OUT), source=self.source,
                   n_car=cnt[0], n_large_vehicle=cnt[1], n_person=cnt[2])
        row.update(card)
        self.rows.append(row)

    def finish(self):
        with open(os.path.join(self.root, 'cards_part.csv'), 'w', newline='') as f:
            w = csv.DictWriter(f, COLS)
            w.writeheader()
            for r in self.rows:
                w.writerow({k: r.get(k, '') for k in COLS})
        print(f'{self.source}: {len(self.rows)} images', dict(Counter(r["split"] for r in self.rows)))


# --------------------------------------------------------------------------- source 1: jekhor
def stage_jekhor():
    """github.com/jekhor/aerial-cars-dataset (2018). Classes: car truck bus minibus cyclist.

    README licence statement:
      * KIT AIS Dataset frames (MOS*.png, MunichStreet02-MOS*.png): CC-BY 3.0, "KIT AIS Data Set"
      * frames of YouTube video https://youtu.be/jdUpsr-K_8A ("use with caution"): the harlem-*.jpg
        frames (1280x720, only non-DJI video frames, same intersection) -> eval_only
      * own DJI videos/photos + Minsk OSM community photos: CC-BY-SA (version not stated)
    """
    g = GitReader(f'{MIRROR}/jekhor+aerial-cars-dataset/repo')
    st = Stager('jekhor')
    cmap = {0: 0, 1: 1, 2: 1, 3: 1, 4: 2}  # car, truck, bus, minibus(van) -> large_vehicle, cyclist -> person
    names = [n for n in g.ls() if n.lower().endswith(('.jpg', '.png'))]
    # views judged by eye from thumbnails
    oblique_stills = {'DJI_0019', 'DJI_0020', 'DJI_0028', 'DJI_0030', 'DJI_0031'}
    skipped = []
    for n in sorted(names):
        stem = os.path.splitext(n)[0]
        lic, url, attr, view, split, notes = None, None, None, 'nadir', None, ''
        if stem.startswith('harlem-'):
            grp = 'youtube_jdUpsr-K_8A'
            lic, url = 'LicenseRef-YouTube-Standard', 'https://www.youtube.com/static?template=terms'
            attr = 'frames of https://youtu.be/jdUpsr-K_8A via jekhor/aerial-cars-dataset'
            split, notes = 'eval_only', 'YouTube standard licence; README: use with caution'
        elif stem.startswith('MunichStreet02-MOS'):
            grp = 'kit_ais_MunichStreet02'
        elif stem.startswith('MOS'):
            k = int(stem[3:])
            grp = 'kit_ais_seq_MOS74-93' if k < 100 else 'kit_ais_seq_MOS155-179'
        elif stem.startswith(('DJI-00760', 'DJI_0762')):
            # added in commit "Add new images from Minsk" / "Add images" (May 2018), summer scenes;
            # videos 0760 & 0762 consecutive -> treated as one flight
            grp = 'minsk_video_0760_0762'
        elif stem.startswith('DJI_'):
            # DJI_0005 / DJI_0013 videos + DJI_0006..0031 stills share the DJI file counter; the stills' EXIF
            # dates are all 2018-03-26 17:41-18:06, same intersection -> one session/group.
            grp = 'minsk_20180326'
            if stem in oblique_stills:
                view = 'oblique'
        else:  # yakubava.jpg: blob missing (>=4MiB) and empty label; origin unclear -> leave out
            skipped.append(n)
            continue
        if lic is None:
            if grp.startswith('kit_ais'):
                lic, url = 'CC-BY-3.0', LIC['CC-BY-3.0']
                attr = ('"KIT AIS Data Set", Karlsruhe Institute of Technology IPF '
                        '(http://www2.ipf.kit.edu/Personen/schmidt/KIT_AIS_Vehicles_Training_Data_Set.7z); '
                        'labels Yauhen Kharuzhy, github.com/jekhor/aerial-cars-dataset')
                notes = 'aerial (aircraft) nadir image sequence'
            else:
                lic, url = 'CC-BY-SA-4.0', LIC['CC-BY-SA-4.0']
                attr = ('(c) Yauhen Kharuzhy and Minsk OpenStreetMap community, '
                        'github.com/jekhor/aerial-cars-dataset')
                notes = 'README says "CC-BY-SA" without version; 4.0 assumed'
        data = g.read(n)
        if data is None:
            skipped.append(n + ' (blob absent: >=4MiB)')
            continue
        lab = g.read(stem + '.txt') or b''
        boxes = []
        for line in lab.decode().splitlines():
            p = line.split()
            if len(p) == 5:
                boxes.append((cmap[int(p[0])],) + tuple(float(x) for x in p[1:]))
        if split is None:
            split = JEKHOR_SPLIT.get(grp, 'train')
        notes = (notes + '; ' if notes else '') + 'vehicle-only labels: persons/cyclists NOT annotated'
        st.add(n, data, boxes, group=grp, split=split, licence=lic, licence_url=url, attribution=attr,
               view=view, altitude_m='', modality='rgb', orig_name=n, notes=notes)
    g.close()
    st.finish()
    print('jekhor skipped:', skipped)


# held-out groups (whole groups). Trainable groups: 3 KIT sequences, 2 Minsk sessions.
JEKHOR_SPLIT = {
    'minsk_video_0760_0762': 'test',      # 19 imgs, drone video, summer; different date from train session
    'kit_ais_seq_MOS74-93': 'val',        # 20 imgs
}


# --------------------------------------------------------------------------- source 2: HIT-UAV
# group = date_captured + day(0)/night(1) flag from the file name (T_H_A_S_N.jpg: daynight, altitude,
# camera angle, -, frame no.). Frame numbers are a global counter, contiguous within each group.
# Held-out assignment by whole capture DATE (both day and night sessions of that date go together).
HIT_SPLIT = {
    '20210116': 'test',   # day 111 imgs (376 person) + night 204 imgs (798 person, 1169 car, 20 other veh.)
    '20210114': 'test',   # night 162 imgs (1312 person)
    '20210119': 'val',    # day 148 + night 168 imgs
}


def stage_hit_uav():
    """github.com/suojiashun/HIT-UAV-Infrared-Thermal-Dataset, LICENSE = CC BY 4.0 (full legal text)."""
    repo = f'{MIRROR}/suojiashun+HIT-UAV-Infrared-Thermal-Dataset/repo'
    g = GitReader(repo)
    st = Stager('hit_uav')
    # json categories: 0 Person, 1 Car, 2 Bicycle, 3 OtherVehicle, 4 DontCare
    cmap = {0: 2, 1: 0, 3: 1}   # Bicycle (mostly parked bikes / e-bikes) and DontCare dropped
    for osplit in ('train', 'val', 'test'):
        d = json.loads(g.read(f'normal_json/annotations/{osplit}.json'))
        anns = defaultdict(list)
        for a in d['annotation']:
            anns[a['image_id']].append(a)
        for im in d['images']:
            fn = im['filename']
            dn, alt, ang, _x, fr = os.path.splitext(fn)[0].split('_')
            W, H = im['width'], im['height']
            boxes, dropped = [], Counter()
            for a in anns[im['id']]:
                c = a['category_id']
                if c not in cmap:
                    dropped[{2: 'bicycle', 4: 'dontcare'}.get(c, str(c))] += 1
                    continue
                x, y, w, h = a['bbox']
                boxes.append((cmap[c], (x + w / 2) / W, (y + h / 2) / H, w / W, h / H))
            data = g.read(f'normal_json/{osplit}/{fn}')
            if data is None:
                print('missing', fn)
                continue
            date = im['date_captured']
            grp = f'hit_{date}_{"night" if dn == "1" else "day"}'
            notes = f'orig_split={osplit}'
            if dropped:
                notes += ';dropped=' + ','.join(f'{k}:{v}' for k, v in sorted(dropped.items()))
            st.add(fn, data, boxes, group=grp, split=HIT_SPLIT.get(date, 'train'), licence='CC-BY-4.0',
                   licence_url=LIC['CC-BY-4.0'],
                   attribution=('HIT-UAV, J. Suo et al., Scientific Data 10, 227 (2023), '
                                'https://github.com/suojiashun/HIT-UAV-Infrared-Thermal-Dataset'),
                   view='nadir' if int(ang) >= 90 else 'oblique', altitude_m=alt, modality='thermal',
                   angle_deg=ang, orig_name=fn, notes=notes)
    g.close()
    st.finish()


# --------------------------------------------------------------------------- source 3: CATS Lab (eval only)
def stage_cats_lab():
    """github.com/CATS-Lab/Field-data-Drone-View-Vehicle-Image-Set (Keke Long, UW-Madison CATS Lab, 2024).

    Nadir drone video of Park Street, Madison (2022), 640x640 cuts, one class 'car' (all vehicles).
    The repository has NO licence file and the README states no licence -> all rights reserved -> eval_only.
    Pedestrians are visible but NOT annotated: use only for car/vehicle recall evaluation.
    """
    g = GitReader(f'{MIRROR}/CATS-Lab+Field-data-Drone-View-Vehicle-Image-Set/repo')
    st = Stager('cats_lab')
    for n in sorted(x for x in g.ls() if x.startswith('images/')):
        base = n[len('images/'):]
        stem = os.path.splitext(base)[0]
        data = g.read(n)
        lab = g.read(f'labels/{stem}.txt')
        if data is None or lab is None:
            continue
        boxes = []
        for line in lab.decode().splitlines():
            p = line.split()
            if len(p) == 5 and p[0] == '0':
                boxes.append((0,) + tuple(float(x) for x in p[1:]))
        grp = 'cats_drone2' if stem.startswith('Drone2') else 'cats_drone1'
        st.add(base.replace('(', '').replace(')', ''), data, boxes, group=grp, split='eval_only',
               licence='LicenseRef-none-stated',
               licence_url='https://github.com/CATS-Lab/Field-data-Drone-View-Vehicle-Image-Set',
               attribution='CATS Lab (UW-Madison), Drone-View-Vehicle-Image-Set, developer Keke Long',
               view='nadir', altitude_m='', modality='rgb', orig_name=n,
               notes='no licence stated; class car covers all vehicles (trucks/buses not separated); '
                     'persons NOT annotated')
    g.close()
    st.finish()


# --------------------------------------------------------------------------- source 4: AU-AIR sample (eval only)
AUAIR_CLASS = {'Car': 0, 'Truck': 1, 'Van': 1, 'Bus': 1, 'Trailer': 1, 'Human': 2}  # Motorbike, Bicycle: not ours


def stage_auair():
    """github.com/sunw71/auairdataset, examples/auair_subset: 80 frames of AU-AIR (Bozcan and Kayacan, 2020), a
    Parrot Bebop 2 over traffic in Aarhus, low oblique colour views from 4.8-30 m, 1920x1080, 10 frames from each
    of 8 flights (file name frame_<flight start>_x_<n>.jpg -> group = flight).

    Labels: annotations.json, per frame ``bbox`` [{top, left, height, width, class}] in pixels, classes Human, Car,
    Truck, Van, Motorbike, Bicycle, Bus, Trailer (its ``categories``); the file's ``licenses`` are CC BY-NC-SA 2.0 and
    CC BY-NC 2.0 -> non-commercial -> eval_only. Its boxes are drawn loosely and a row of parked cars is sometimes
    one box, so score it at IoU 0.3 beside 0.5 (docs/results/detection.md).
    """
    g = GitReader(f'{MIRROR}/sunw71+auairdataset/repo')
    ann = json.loads(g.read('examples/auair_subset/annotations.json'))
    cats = ann['categories']
    st = Stager('auair')
    for a in ann['annotations']:
        name = a['image_name']
        data = g.read(f'examples/auair_subset/images/{name}')
        if data is None:
            continue
        w, h = float(a['image_width']), float(a['image_height'])
        boxes = [(AUAIR_CLASS[cats[b['class']]], (b['left'] + b['width'] / 2) / w, (b['top'] + b['height'] / 2) / h,
                  b['width'] / w, b['height'] / h) for b in a['bbox'] if cats[b['class']] in AUAIR_CLASS]
        st.add(name, data, boxes, group='auair_' + name.split('_')[1], split='eval_only',
               licence='CC-BY-NC-SA-2.0', licence_url='https://creativecommons.org/licenses/by-nc-sa/2.0/',
               attribution='AU-AIR dataset, I. Bozcan and E. Kayacan (Aarhus University), subset in sunw71/auairdataset',
               view='oblique', altitude_m=round(a['altitude'] / 1000.0, 1), modality='rgb', orig_name=name,
               notes='non-commercial licence; loose boxes, some rows of parked cars boxed as one')
    g.close()
    st.finish()


# --------------------------------------------------------------------------- source 5: UAV search and rescue (eval only)
def stage_sar_persons():
    """github.com/gvessio/uav-search-and-rescue (Castellano et al., 2020): 310 frames of oblique colour drone video
    found on YouTube, beaches (110) and mountains (200), half with persons; YOLO labels, class 1 = person.

    No licence file; its README: "intended for testing and evaluation purposes only" -> eval_only. The frames are
    not named by video, so each scene is one group.
    """
    g = GitReader(f'{MIRROR}/gvessio+uav-search-and-rescue/repo')
    st = Stager('sar_persons')
    files = set(g.ls())
    for n in sorted(x for x in files if '/frames/' in x):
        scene, stem = n.split('/')[1], os.path.splitext(os.path.basename(n))[0]
        data, lab = g.read(n), g.read(f'dataset/{scene}/annotations/{stem}.txt')
        if data is None:
            continue
        boxes = [(2,) + tuple(float(x) for x in p[1:]) for p in (line.split() for line in
                 (lab or b'').decode().splitlines()) if len(p) == 5 and p[0] == '1']
        st.add(f'{scene}_{stem}{os.path.splitext(n)[1]}', data, boxes, group=f'sar_{scene}', split='eval_only',
               licence='LicenseRef-evaluation-only', licence_url='https://github.com/gvessio/uav-search-and-rescue',
               attribution='G. Castellano, D. Carone, F. Scigliuto, G. Vessio, doi:10.5281/zenodo.3924925',
               view='oblique', altitude_m='', modality='rgb', orig_name=n,
               notes='README: for testing and evaluation only; YouTube footage; only persons labelled')
    g.close()
    st.finish()


# --------------------------------------------------------------------------- driver
SOURCES = {'jekhor': stage_jekhor, 'hit_uav': stage_hit_uav, 'cats_lab': stage_cats_lab, 'auair': stage_auair,
           'sar_persons': stage_sar_persons}


def merge_cards():
    rows = []
    for s in sorted(os.listdir(OUT)):
        p = os.path.join(OUT, s, 'cards_part.csv')
        if os.path.isfile(p):
            with open(p, newline='') as f:
                rows += list(csv.DictReader(f))
    with open(os.path.join(OUT, 'cards.csv'), 'w', newline='') as f:
        w = csv.DictWriter(f, COLS)
        w.writeheader()
        w.writerows(rows)
    return rows


def summary(rows):
    out = []
    by = defaultdict(lambda: Counter())
    for r in rows:
        k = (r['source'], r['split'])
        by[k]['images'] += 1
        for c in ('n_car', 'n_large_vehicle', 'n_person'):
            by[k][c] += int(r[c])
    for k in sorted(by):
        v = by[k]
        out.append(f'{k[0]} {k[1]}: {v["images"]} images, car {v["n_car"]}, large_vehicle '
                   f'{v["n_large_vehicle"]}, person {v["n_person"]}')
    tot = Counter(r['split'] for r in rows)
    out.append('TOTAL per split (lines in cards.csv): ' + ', '.join(f'{k} {v}' for k, v in sorted(tot.items())))
    return '\n'.join(out)


if __name__ == '__main__':
    want = sys.argv[1:] or list(SOURCES)
    for s in want:
        SOURCES[s]()
    rows = merge_cards()
    print(summary(rows))
