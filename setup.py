"""ament_python package stockpile_ros; also a plain pip-installable Python package."""

from glob import glob

from setuptools import find_packages, setup

PACKAGE = 'stockpile_ros'

setup(
    name=PACKAGE,
    version='0.1.0',
    packages=find_packages(exclude=['tests', 'tests.*']),
    # The report page's template is read with jinja2's PackageLoader.
    package_data={'stockpile_ros.segment': ['templates/*.j2']},
    data_files=[
        ('share/ament_index/resource_index/packages', [f'resource/{PACKAGE}']),
        (f'share/{PACKAGE}', ['package.xml']),
        (f'share/{PACKAGE}/launch', glob('launch/*.py')),
        (f'share/{PACKAGE}/config', glob('config/*')),
        (f'share/{PACKAGE}/dashboards', glob('dashboards/*')),
        # The message schemas travel with the Python package so that bag replay can register them
        # with the rosbags typestore on machines that never built the interface package.
        (f'share/{PACKAGE}/msg_schemas/msg', glob('msg_schemas/msg/*.msg')),
    ],
    python_requires='>=3.10',
    install_requires=[
        'numpy>=1.26',
        'scipy>=1.11',
        'opencv-python-headless>=4.8,<5',
        'open3d-cpu>=0.19; platform_machine=="x86_64"',
        'open3d>=0.19; platform_machine!="x86_64"',
        'pycolmap>=3.11',
        'Pillow>=9.4',
        # HEIC/HEIF photos (iPhones' default); without it they are refused with the fix named.
        'pillow-heif>=0.16',
        # 0.11: offered QoS per connection; the writer relies on its <folder>/<folder>.mcap naming.
        'rosbags>=0.11,<0.12',
        'tqdm>=4.60',
        'matplotlib>=3.7',
        'PyYAML>=6',
        'jinja2>=3.1',
    ],
    extras_require={
        # mcap: an independent reader to check the MCAP files we write (chunks, channel metadata).
        'test': [
            'pytest>=7',
            'ruff>=0.5',
            'mypy>=1.10',
            'types-PyYAML',
            'mcap>=1.1,<2',
            'hypothesis>=6',
            # renders the printed targets' PDF pages to check them (tests/test_target_pages.py).
            'pypdfium2>=4',
        ],
    },
    zip_safe=True,
    maintainer='stockpile_ros maintainers',
    maintainer_email='maintainers@stockpile-ros.invalid',
    description='Measure the rocks of a stockpile from a moving camera (ROS 2 Jazzy).',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'stockpile = stockpile_ros.cli:main',
            'keyframe_node = stockpile_ros.nodes.keyframe_node:main',
            'reconstruction_node = stockpile_ros.nodes.reconstruction_node:main',
            'segmentation_node = stockpile_ros.nodes.segmentation_node:main',
            'rig = stockpile_ros.nodes.rig:main',
            'stockpile-play = stockpile_ros.nodes.player:main',
        ],
    },
)
